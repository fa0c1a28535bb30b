//! The second stage's tools, shared by every section: [`ConfigError`] (naming the file, the line
//! and the key), the [`Checker`] that turns toml's byte spans into lines, and the range checks
//! more than one section uses.

use std::path::{Path, PathBuf};

use toml::Spanned;

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read the configuration file {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// Not valid TOML, or a key brdfd does not know, or a value of the wrong type.
    #[error("{origin}:{line}:{column}: {message}{}", key_suffix(.key))]
    Syntax {
        /// The file (or "brdfd.toml" for text not read from a file).
        origin: String,
        line: usize,
        column: usize,
        /// The dotted key concerned, when toml says.
        key: Option<String>,
        message: String,
    },

    /// A well-formed value that is not acceptable (out of range, not loopback, unknown name).
    #[error("{origin}:{}{key}: {message}", line_prefix(*.line))]
    Invalid {
        origin: String,
        /// The line of the offending value; `None` when the value is a default.
        line: Option<usize>,
        /// The dotted key, e.g. `api.listen`.
        key: &'static str,
        message: String,
    },
}

fn key_suffix(key: &Option<String>) -> String {
    key.as_ref()
        .map(|k| format!(" (key `{k}`)"))
        .unwrap_or_default()
}

fn line_prefix(line: Option<usize>) -> String {
    line.map(|l| format!("{l}: ")).unwrap_or_else(|| " ".into())
}

/// A raw value with its place in the text: absent, or what the file says and where.
pub(super) type S<T> = Option<Spanned<T>>;

/// Turns byte offsets into line numbers and builds errors for one text.
pub(super) struct Checker<'a> {
    pub(super) text: &'a str,
    pub(super) origin: &'a str,
    /// Whether `[devices.*] transport` must be set (always, for a file read by brdfd).
    pub(super) require_transport: bool,
    /// The directory of the file read, which relative paths in it are relative to; `None` for
    /// text not read from a file (its paths are kept as written).
    pub(super) base: Option<&'a Path>,
}

impl Checker<'_> {
    /// 1-based line and column of byte `offset`.
    fn position(&self, offset: usize) -> (usize, usize) {
        let before = &self.text[..offset.min(self.text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        (line, column)
    }

    pub(super) fn invalid<T>(
        &self,
        key: &'static str,
        value: &Spanned<T>,
        message: String,
    ) -> ConfigError {
        ConfigError::Invalid {
            origin: self.origin.to_string(),
            line: Some(self.position(value.span().start).0),
            key,
            message,
        }
    }

    /// The value of `key` or its default, checked by `check`.
    pub(super) fn value<T: Clone, U>(
        &self,
        key: &'static str,
        raw: &S<T>,
        default: T,
        check: impl FnOnce(T) -> Result<U, String>,
    ) -> Result<U, ConfigError> {
        match raw {
            Some(v) => check(v.get_ref().clone()).map_err(|m| self.invalid(key, v, m)),
            None => check(default).map_err(|message| ConfigError::Invalid {
                origin: self.origin.to_string(),
                line: None,
                key,
                message,
            }),
        }
    }

    /// An optional path: absent, or a non-empty string.
    pub(super) fn path(
        &self,
        key: &'static str,
        raw: &S<String>,
    ) -> Result<Option<PathBuf>, ConfigError> {
        match raw {
            None => Ok(None),
            Some(v) if v.get_ref().trim().is_empty() => Err(self.invalid(
                key,
                v,
                "must not be empty; leave the key out instead".into(),
            )),
            Some(v) => Ok(Some(self.resolve(v.get_ref()))),
        }
    }

    /// A path as the file writes it: a relative one is relative to the file's directory
    /// (never the working directory of whoever reads the file, daemon or command).
    pub(super) fn resolve(&self, path: &str) -> PathBuf {
        let p = PathBuf::from(path);
        match self.base {
            Some(base) if p.is_relative() => base.join(p),
            _ => p,
        }
    }

    pub(super) fn syntax(&self, mut e: toml::de::Error) -> ConfigError {
        let (line, column) = self.position(e.span().map_or(0, |s| s.start));
        let message = e.message().trim_end().to_string();
        // toml only says which table a key sits in through its Display without the input
        // ("… in `devices.sra`").
        e.set_input(None);
        let key = e
            .to_string()
            .lines()
            .filter_map(|l| l.strip_prefix("in `")?.strip_suffix('`'))
            .next_back()
            .map(str::to_string);
        // For an unknown key toml names the table it sits in; name the key itself.
        let unknown = message
            .strip_prefix("unknown field `")
            .and_then(|m| m.split_once('`'))
            .map(|(k, _)| k.to_string());
        let key = match (key, unknown) {
            (Some(table), Some(k)) => Some(format!("{table}.{k}")),
            (None, Some(k)) => Some(k),
            (key, None) => key,
        };
        ConfigError::Syntax {
            origin: self.origin.to_string(),
            line,
            column,
            key,
            message,
        }
    }
}

pub(super) fn bounded_count(n: u64, lo: u64, hi: u64) -> Result<usize, String> {
    if (lo..=hi).contains(&n) {
        Ok(n as usize)
    } else {
        Err(format!("{n} is out of range: {lo} to {hi}"))
    }
}

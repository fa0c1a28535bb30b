//! The API token: made at the first start, kept in a private file, compared in constant time.

use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};

use rand::RngCore;

/// The API token: 64 hex digits (256 bits).
#[derive(Clone, PartialEq, Eq)]
pub struct Token(String);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never in logs or panic messages.
        f.write_str("Token(…)")
    }
}

/// Why the token could not be loaded or created.
#[derive(Debug, thiserror::Error)]
pub enum TokenError {
    #[error(
        "cannot read the API token file {path}: {source}; run brdfd as the user that owns it, or set [api] token_file"
    )]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "cannot create the API token file {path}: {source}; check that its directory exists and is writable by brdfd's user, or set [api] token_file"
    )]
    Create {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "the API token file {path} holds no token (expected at least 32 hex digits on one line); delete it and restart brdfd serve to make a new one"
    )]
    Malformed { path: PathBuf },
    #[error(
        "the API token file {path} is not a regular file (a pipe, device or folder); remove it \
         and restart brdfd serve to make a new one, or set [api] token_file to a file"
    )]
    NotRegular { path: PathBuf },
    #[error(
        "the API token file {path} can be read by other users (mode {mode:o}); run `chmod 600 {path}` (or 640 with brdfd's group)"
    )]
    TooOpen { path: PathBuf, mode: u32 },
}

impl Token {
    /// A new random token.
    pub fn generate() -> Token {
        let mut bytes = [0u8; 32];
        rand::rng().fill_bytes(&mut bytes);
        Token(hex::encode(bytes))
    }

    /// A token from text (a file's content or `BRDFD_TOKEN`): at least 32 hex digits.
    pub fn parse(text: &str) -> Option<Token> {
        let t = text.trim();
        (t.len() >= 32 && t.len() <= 256 && t.bytes().all(|b| b.is_ascii_hexdigit()))
            .then(|| Token(t.to_string()))
    }

    /// The token as sent in `Authorization: Bearer …`.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Reads the token file, checking that it is a regular file (a FIFO or a device would hang
    /// or feed the read) that other users cannot read.
    pub fn read(path: &Path) -> Result<Token, TokenError> {
        use std::io::Read;
        use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
        let read_err = |source| TokenError::Read {
            path: path.to_path_buf(),
            source,
        };
        crate::safe_fs::protect(path, "the API token file");
        // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer.
        let file = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)
            .map_err(read_err)?;
        let meta = file.metadata().map_err(read_err)?;
        if !meta.is_file() {
            return Err(TokenError::NotRegular {
                path: path.to_path_buf(),
            });
        }
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o007 != 0 {
            return Err(TokenError::TooOpen {
                path: path.to_path_buf(),
                mode,
            });
        }
        let mut text = String::new();
        // A token is 64 hex digits; a few KiB is more than any valid file.
        file.take(4096)
            .read_to_string(&mut text)
            .map_err(read_err)?;
        Token::parse(&text).ok_or_else(|| TokenError::Malformed {
            path: path.to_path_buf(),
        })
    }

    /// The daemon's token: read from `path`, or created there on first start (mode 0600, or
    /// 0640 under systemd, where the unit's group lets operators in that group read it).
    /// Returns the token and whether it was created now.
    pub fn load_or_create(path: &Path) -> Result<(Token, bool), TokenError> {
        match Token::read(path) {
            Ok(t) => return Ok((t, false)),
            Err(TokenError::Read { source, .. })
                if source.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        let token = Token::generate();
        let mut options = OpenOptions::new();
        options.write(true).create_new(true);
        {
            use std::os::unix::fs::OpenOptionsExt;
            options
                .mode(crate::safe_fs::private_mode())
                .custom_flags(libc::O_NOFOLLOW);
        }
        let create = |source| TokenError::Create {
            path: path.to_path_buf(),
            source,
        };
        let mut file = options.open(path).map_err(create)?;
        writeln!(file, "{}", token.as_str()).map_err(create)?;
        file.sync_all().map_err(create)?;
        Ok((token, true))
    }

    /// Constant-time comparison with what a request sent.
    pub(super) fn matches(&self, sent: &[u8]) -> bool {
        constant_time_eq(self.0.as_bytes(), sent)
    }
}

/// Whether two byte strings are equal, in time that depends only on their lengths.
pub(super) fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_token_is_256_random_bits_in_hex() {
        let a = Token::generate();
        let b = Token::generate();
        assert_eq!(a.as_str().len(), 64);
        assert!(a.as_str().bytes().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(a, b);
        assert_eq!(format!("{a:?}"), "Token(…)");
        assert!(Token::parse("abc").is_none());
        assert!(Token::parse(&"g".repeat(64)).is_none());
        assert_eq!(Token::parse(&format!("{}\n", a.as_str())), Some(a));
    }

    #[test]
    fn the_token_file_is_created_private_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("brdfd.token");
        let (t, created) = Token::load_or_create(&path).unwrap();
        assert!(created);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode & 0o077 & !0o040, 0, "mode {mode:o}");
        }
        let (again, created) = Token::load_or_create(&path).unwrap();
        assert!(!created);
        assert_eq!(t, again);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
            let e = Token::load_or_create(&path).unwrap_err();
            assert!(e.to_string().contains("chmod 600"), "{e}");
        }
        std::fs::write(dir.path().join("bad"), "not a token").unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(
                dir.path().join("bad"),
                std::fs::Permissions::from_mode(0o600),
            )
            .unwrap();
        }
        let e = Token::read(&dir.path().join("bad")).unwrap_err();
        assert!(e.to_string().contains("delete it"), "{e}");
    }

    #[test]
    fn a_token_file_that_is_a_pipe_is_refused_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("brdfd.token");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let started = std::time::Instant::now();
        let e = Token::load_or_create(&fifo).unwrap_err();
        assert!(matches!(e, TokenError::NotRegular { .. }), "{e}");
        assert!(e.to_string().contains("not a regular file"), "{e}");
        assert!(started.elapsed() < Duration::from_secs(1));
    }
}

//! `brdfd completions SHELL` and `brdfd man`: what a packaged command-line tool ships beside the
//! binary, generated from the same clap definition as `--help` (clap_complete, clap_mangen), so
//! they can never disagree with it.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::CommandFactory;

use super::Cli;

#[derive(Debug, clap::Args)]
#[command(after_help = "Install, e.g.:\n  \
    brdfd completions bash > ~/.local/share/bash-completion/completions/brdfd\n  \
    brdfd completions zsh > \"${fpath[1]}/_brdfd\"\n  \
    brdfd completions fish > ~/.config/fish/completions/brdfd.fish")]
pub struct CompletionsArgs {
    /// The shell to complete for.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

#[derive(Debug, clap::Args)]
#[command(after_help = "Read it with `brdfd man | man -l -`; install with \
    `brdfd man --out /usr/local/share/man/man1`.")]
pub struct ManArgs {
    /// Write brdfd.1 and one page per subcommand (brdfd-scan.1, …) into this directory instead
    /// of printing brdfd.1 to stdout.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// Prints the completion script for `args.shell`.
pub fn completions(args: &CompletionsArgs) -> anyhow::Result<()> {
    let mut cmd = Cli::command();
    let mut out = std::io::stdout().lock();
    clap_complete::generate(args.shell, &mut cmd, "brdfd", &mut out);
    out.flush().context("writing the completion script")?;
    Ok(())
}

/// Prints (or writes) the man pages.
pub fn man(args: &ManArgs) -> anyhow::Result<()> {
    let cmd = Cli::command();
    match &args.out {
        None => {
            let mut out = std::io::stdout().lock();
            clap_mangen::Man::new(cmd)
                .render(&mut out)
                .context("writing the man page")?;
            out.flush().context("writing the man page")?;
        }
        Some(dir) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            clap_mangen::generate_to(cmd, dir)
                .with_context(|| format!("writing the man pages into {}", dir.display()))?;
            println!("man pages written to {}", dir.display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_subcommand_is_completed_and_documented() {
        let mut cmd = Cli::command();
        let mut bash = Vec::new();
        clap_complete::generate(clap_complete::Shell::Bash, &mut cmd, "brdfd", &mut bash);
        let bash = String::from_utf8(bash).unwrap();
        let mut page = Vec::new();
        clap_mangen::Man::new(Cli::command())
            .render(&mut page)
            .unwrap();
        let page = String::from_utf8(page).unwrap();
        assert!(page.starts_with(".ie"), "{}", &page[..80]);
        for sub in Cli::command().get_subcommands() {
            let name = sub.get_name();
            assert!(bash.contains(name), "bash completion lacks {name}");
            // roff writes a hyphen as `\-`.
            let roff = name.replace('-', "\\-");
            assert!(page.contains(&roff), "man page lacks {name}");
        }
    }
}

//! The `brdfd` binary: parse the command line, run it, and on failure print the error chain on
//! one line to stderr with a non-zero exit status that says what kind of failure it was
//! (`cli::EXIT_CODES_HELP`: 2 usage, 3 no daemon, 4 busy, 5 not authorised, 6 refused, 1
//! otherwise).

use std::process::ExitCode;

use clap::Parser;
use clap::error::ErrorKind;

use brdfd::cli::{self, Cli};

fn main() -> ExitCode {
    let parsed = match Cli::try_parse() {
        Ok(parsed) => parsed,
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            // `brdfd` alone: the help is the most useful answer.
            let _ = e.print();
            return ExitCode::from(2);
        }
        Err(e) => {
            eprintln!("error: {}", cli::usage_error_line(&e));
            return ExitCode::from(cli::exit::USAGE);
        }
    };
    if !matches!(parsed.command, cli::Command::Serve(_)) {
        stop_quietly_on_closed_pipe();
    }
    match cli::run(parsed) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", cli::one_line(&e));
            ExitCode::from(cli::exit_code(&e))
        }
    }
}

/// `brdfd scans | head` should end quietly when `head` closes the pipe, as other Unix tools do,
/// instead of panicking inside `println!`. Rust ignores SIGPIPE by default; the default action
/// is restored for every command but `serve`, which keeps ignoring it so that nothing a client
/// does can kill the daemon (socket writes use MSG_NOSIGNAL and never raise it anyway).
fn stop_quietly_on_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: called once at start-up before any thread is spawned; SIG_DFL is a valid handler.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

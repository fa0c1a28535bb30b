//! `brdfd open`: a one-time login link to the operator's web page.
//!
//! The page cannot be given the API token (a script could leak it), so `open`, which has the
//! token, asks the daemon for a login ticket (`POST /session/ticket`) and prints
//! `http://ADDR/login?ticket=…`. Opening that link once sets the page's session cookie (see
//! `api::access`); the link is then spent, and expires after two minutes if unused. On a
//! desktop (`DISPLAY` or `WAYLAND_DISPLAY` set) the link is also opened with `xdg-open`.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::process::{Command, Stdio};

use anyhow::Context;
use serde_json::json;

use super::operator::DaemonArgs;

#[derive(Debug, clap::Args)]
#[command(after_help = "\
The link works once and for two minutes; the session it opens lasts 12 hours (or until the
page's Log out, or a new API token). Anyone who can read the API token can run this command.

Examples:
  brdfd open                 # print the link, and open it where a desktop is present
  brdfd open --no-browser    # print it only (e.g. over ssh, to paste into a local browser
                             # through a tunnel: ssh -L 7878:127.0.0.1:7878 lab-pc)")]
pub struct OpenArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Print the link without trying to open a browser.
    #[arg(long)]
    pub no_browser: bool,
    /// Print `{"url": …, "expires_in_s": …}` instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The address a browser on this machine should use for a daemon listening on `addr`: an
/// unspecified address (0.0.0.0, ::) is reached through loopback.
pub fn browser_addr(addr: SocketAddr) -> SocketAddr {
    match addr.ip() {
        IpAddr::V4(ip) if ip.is_unspecified() => {
            SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), addr.port())
        }
        IpAddr::V6(ip) if ip.is_unspecified() => {
            SocketAddr::new(IpAddr::V6(Ipv6Addr::LOCALHOST), addr.port())
        }
        _ => addr,
    }
}

pub fn run(args: &OpenArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let answer = client
        .ticket()
        .context("asking the daemon for a login link")?;
    let expires = answer.expires_in_s;
    let url = format!("http://{}{}", browser_addr(client.addr()), answer.path);
    let desktop =
        std::env::var_os("DISPLAY").is_some() || std::env::var_os("WAYLAND_DISPLAY").is_some();
    let opened = !args.no_browser && desktop && open_in_browser(&url);
    if args.json {
        println!(
            "{}",
            json!({ "url": url, "expires_in_s": expires, "opened": opened })
        );
    } else {
        println!("{url}");
        if opened {
            eprintln!("opened in the browser; the link works once, within {expires} s");
        } else {
            eprintln!(
                "open this link in a browser on this machine; it works once, within {expires} s"
            );
        }
    }
    Ok(())
}

/// Starts `xdg-open URL` without waiting for the browser; whether it could be started.
fn open_in_browser(url: &str) -> bool {
    match Command::new("xdg-open")
        .arg(url)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
    {
        Ok(_) => true,
        Err(e) => {
            tracing::debug!(error = %e, "xdg-open");
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unspecified_listen_address_is_reached_through_loopback() {
        let a: SocketAddr = "0.0.0.0:7878".parse().unwrap();
        assert_eq!(browser_addr(a), "127.0.0.1:7878".parse().unwrap());
        let a: SocketAddr = "[::]:7878".parse().unwrap();
        assert_eq!(browser_addr(a), "[::1]:7878".parse().unwrap());
        let a: SocketAddr = "127.0.0.1:9".parse().unwrap();
        assert_eq!(browser_addr(a), a);
    }
}

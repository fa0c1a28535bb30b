//! A local flood on the HTTP API with the shipped `[api]` bounds (nothing raised): SILENT
//! sockets that connect and send nothing, HALF sockets that send half a request header, and
//! STREAMS `GET /events` subscribers that read nothing, all held open at once, while the
//! operator's `GET /status` (with the token) and the web page's `GET /` are timed. Prints the
//! latencies (10 s of requests), how many streams were served, how often the flood reopened a
//! socket the daemon closed (after its header timeout), and the daemon's own memory (`RssAnon`
//! of this process: the daemon plus the flood's sockets) before and during the flood.
//!
//! `cargo run --release --example api_flood [-- SILENT STREAMS HALF]` (defaults 500 500 100).
//! Exits non-zero if a `/status` took 1 s or more, or failed.

mod common;

use common::percentile;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use brdfd::api::{Access, ApiOptions, ApiServer, Token};
use brdfd::client::Client;

/// This process's anonymous resident memory (heap, stacks), KiB.
fn rss_anon_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("RssAnon:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

fn open_stream(addr: SocketAddr, token: &Token) -> anyhow::Result<Option<TcpStream>> {
    let mut s = TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    write!(
        s,
        "GET /events HTTP/1.1\r\nhost: {addr}\r\nauthorization: Bearer {}\r\n\r\n",
        token.as_str()
    )?;
    let mut seen = Vec::new();
    let mut buf = [0u8; 1024];
    while !seen.windows(4).any(|w| w == b"\r\n\r\n") {
        let n = s.read(&mut buf)?;
        anyhow::ensure!(n > 0, "an event stream closed before its head");
        seen.extend_from_slice(&buf[..n]);
    }
    Ok(seen.starts_with(b"HTTP/1.1 200").then_some(s))
}

fn main() -> anyhow::Result<()> {
    let limit = brdfd::api::server::raise_fd_limit();
    let args = common::counts();
    let silent_count = args.first().copied().unwrap_or(500);
    let stream_count = args.get(1).copied().unwrap_or(500);
    let half_count = args.get(2).copied().unwrap_or(100);
    let dir = tempfile::tempdir()?;
    let rt = common::runtime()?;
    let token = Token::generate();
    let (api, service) = rt.block_on(async {
        let service = common::simulated_service(dir.path()).await?;
        // The shipped bounds: brdfd.toml's [api] as it comes.
        let options = ApiOptions::new(Access::new(token.clone()));
        println!(
            "[api] max_connections {}, max_event_subscribers {}, header_timeout {:?}, idle_timeout {:?}; open files limit {limit}",
            options.connections.max_connections,
            options.max_event_subscribers,
            options.connections.header_timeout,
            options.connections.idle_timeout
        );
        let api = ApiServer::start(service.clone(), "127.0.0.1:0".parse()?, options).await?;
        anyhow::Ok((api, service))
    })?;
    let addr = api.local_addr();
    let client = Client::new(addr).with_token(&token, "flood bench");
    client.get("/status")?;
    let before = rss_anon_kib();

    let opened = Instant::now();
    let mut streams = Vec::new();
    let mut refused = 0;
    for _ in 0..stream_count {
        match open_stream(addr, &token)? {
            Some(s) => streams.push(s),
            None => refused += 1,
        }
    }
    let streams_took = opened.elapsed();
    // The flood: SILENT + HALF sockets, each reopened as soon as the daemon closes it (after
    // the header timeout), so the daemon holds them all for the whole measurement.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flood = {
        let stop = stop.clone();
        std::thread::spawn(move || -> anyhow::Result<(usize, usize)> {
            let open = |half: bool| -> anyhow::Result<TcpStream> {
                let mut s = TcpStream::connect(addr)?;
                if half {
                    s.write_all(b"GET /status HTTP/1.1\r\nhost: 127.0.0.1\r\nx-half: ")?;
                }
                s.set_nonblocking(true)?;
                Ok(s)
            };
            let mut socks = Vec::new();
            for i in 0..silent_count + half_count {
                socks.push((open(i >= silent_count)?, i >= silent_count));
            }
            let mut reopened = 0;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                for (s, half) in &mut socks {
                    let mut b = [0u8; 256];
                    let closed = match s.read(&mut b) {
                        Ok(_) => true,
                        Err(e) => e.kind() != std::io::ErrorKind::WouldBlock,
                    };
                    if closed {
                        *s = open(*half)?;
                        reopened += 1;
                    }
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Ok((socks.len(), reopened))
        })
    };
    println!(
        "{} event streams served ({refused} refused) in {:.0} ms; flood of {silent_count} silent and {half_count} half-sent sockets started",
        streams.len(),
        streams_took.as_secs_f64() * 1e3,
    );
    // Let the flood open its sockets before measuring.
    std::thread::sleep(Duration::from_secs(3));
    let during = rss_anon_kib();

    let mut status = Vec::new();
    let mut page = Vec::new();
    let mut failures = 0;
    let until = Instant::now() + Duration::from_secs(10);
    while Instant::now() < until {
        let t = Instant::now();
        match client.get("/status") {
            Ok(_) => status.push(t.elapsed().as_secs_f64() * 1e3),
            Err(e) => {
                failures += 1;
                eprintln!("GET /status failed: {e}");
            }
        }
        let t = Instant::now();
        let mut s = TcpStream::connect(addr)?;
        s.write_all(b"GET / HTTP/1.1\r\nhost: 127.0.0.1\r\nconnection: close\r\n\r\n")?;
        let mut answer = Vec::new();
        s.read_to_end(&mut answer)?;
        if answer.starts_with(b"HTTP/1.1 200") {
            page.push(t.elapsed().as_secs_f64() * 1e3);
        } else {
            failures += 1;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let (held, reopened) = flood.join().expect("the flood thread")?;
    println!(
        "flood sockets held open throughout: {held}; reopened after the daemon closed them: {reopened}"
    );
    status.sort_by(f64::total_cmp);
    page.sort_by(f64::total_cmp);
    let show = |name: &str, v: &[f64]| {
        println!(
            "{name}: {} answered, p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
            v.len(),
            percentile(v, 0.5),
            percentile(v, 0.99),
            v.last().copied().unwrap_or(f64::NAN)
        );
    };
    show("GET /status (token)", &status);
    show("GET / (the web page)", &page);
    println!(
        "memory (RssAnon): {:.1} MiB before, {:.1} MiB during the flood ({:.1} KiB per connection)",
        before as f64 / 1024.0,
        during as f64 / 1024.0,
        (during.saturating_sub(before)) as f64 / (stream_count + silent_count + half_count) as f64
    );
    drop(streams);
    rt.block_on(async {
        api.stop(Duration::from_secs(1)).await;
        service.shutdown().await;
    });
    anyhow::ensure!(failures == 0, "{failures} requests failed");
    anyhow::ensure!(
        status.last().copied().unwrap_or(f64::INFINITY) < 1000.0,
        "a GET /status took 1 s or more"
    );
    Ok(())
}

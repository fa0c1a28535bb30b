//! Load on the HTTP API, bounded and on loopback only: 500 idle connections and 200 `GET
//! /events` subscribers held open while a reference and a scan are measured on the simulated
//! instruments (recorded timing), with `GET /status` polled throughout. Prints the `/status`
//! latency (p50, p99, max), whether the scan completed, and how many idle connections the
//! server closed after its idle timeout.
//!
//! `cargo run --release --example api_load [-- IDLE SUBSCRIBERS]` (defaults 500 and 200).
//! The API's caps are raised for the run (max_connections 1000, max_event_subscribers 300) and
//! the idle timeout lowered to 5 s; nothing else differs from `brdfd serve`.

mod common;

use common::percentile;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use brdfd::api::{Access, ApiOptions, ApiServer, Token};
use brdfd::client::Client;
use serde_json::json;

const IDLE_TIMEOUT: Duration = Duration::from_secs(5);

fn main() -> anyhow::Result<()> {
    brdfd::api::server::raise_fd_limit();
    let args = common::counts();
    let idle_count = args.first().copied().unwrap_or(500);
    let subscribers = args.get(1).copied().unwrap_or(200);
    let dir = tempfile::tempdir()?;
    let rt = common::runtime()?;
    let token = Token::generate();
    let (api, service) = rt.block_on(async {
        let service = common::simulated_service(dir.path()).await?;
        let mut options = ApiOptions::new(Access::new(token.clone()));
        options.connections.max_connections = 1000;
        options.connections.idle_timeout = IDLE_TIMEOUT;
        options.max_event_subscribers = 300;
        let api = ApiServer::start(service.clone(), "127.0.0.1:0".parse()?, options).await?;
        anyhow::Ok((api, service))
    })?;
    let addr: SocketAddr = api.local_addr();
    let client = Client::new(addr).with_token(&token, "load test");

    // The event subscribers, each read in its own thread until the end of the run.
    let mut streams = Vec::new();
    for _ in 0..subscribers {
        let events = client.events()?;
        streams.push(std::thread::spawn(move || events.count()));
    }
    // The idle connections: connected, nothing sent.
    let opened = Instant::now();
    let mut idle: Vec<TcpStream> = (0..idle_count)
        .map(|_| TcpStream::connect(addr))
        .collect::<Result<_, _>>()?;
    println!(
        "{idle_count} idle connections and {subscribers} event streams open on {addr} ({:.0} ms)",
        opened.elapsed().as_secs_f64() * 1e3
    );

    let mut latencies = Vec::new();
    let poll_until_idle = |latencies: &mut Vec<f64>| -> anyhow::Result<()> {
        loop {
            let t = Instant::now();
            let status = client.get("/status")?;
            latencies.push(t.elapsed().as_secs_f64() * 1e3);
            if status["busy"].is_null() {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    client.post("/reference", None)?;
    poll_until_idle(&mut latencies)?;
    let scan = client.post("/scans", Some(&json!({"sample": "T.Sky blue"})))?["scan"]
        .as_i64()
        .unwrap_or(-1);
    poll_until_idle(&mut latencies)?;
    let state = client.get(&format!("/scans/{scan}"))?["scan"]["state"].clone();
    latencies.sort_by(f64::total_cmp);
    println!(
        "GET /status during the reference and the scan: {} requests, p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        latencies.len(),
        percentile(&latencies, 0.5),
        percentile(&latencies, 0.99),
        latencies.last().copied().unwrap_or(f64::NAN)
    );
    println!("scan {scan}: {state}");

    // The idle connections are closed by the server once idle for IDLE_TIMEOUT.
    let deadline = opened + IDLE_TIMEOUT + Duration::from_secs(10);
    let mut closed = 0;
    for s in &mut idle {
        let left = deadline.saturating_duration_since(Instant::now());
        s.set_read_timeout(Some(left.max(Duration::from_millis(1))))?;
        let mut b = [0u8; 64];
        if matches!(s.read(&mut b), Ok(0)) {
            closed += 1;
        }
    }
    println!(
        "idle connections closed by the server within {:?} of opening: {closed} of {idle_count}",
        IDLE_TIMEOUT + Duration::from_secs(10)
    );
    // A request still works after all that.
    let mut s = TcpStream::connect(addr)?;
    s.write_all(b"GET /healthz HTTP/1.1\r\nhost: 127.0.0.1\r\nconnection: close\r\n\r\n")?;
    let mut answer = String::new();
    s.read_to_string(&mut answer)?;
    println!("afterwards: {}", answer.lines().next().unwrap_or(""));

    rt.block_on(async {
        api.stop(Duration::from_secs(1)).await;
        service.shutdown().await;
    });
    let events_seen: usize = streams.into_iter().map(|h| h.join().unwrap_or(0)).sum();
    println!("events delivered to the {subscribers} subscribers: {events_seen}");
    anyhow::ensure!(state == "complete", "the scan did not complete: {state}");
    anyhow::ensure!(
        closed == idle_count,
        "{} idle connections left open",
        idle_count - closed
    );
    Ok(())
}

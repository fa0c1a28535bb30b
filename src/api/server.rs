//! The HTTP server under the API: an accept loop on hyper's HTTP/1.1 connection builder, so that
//! every connection has bounds a stray or hostile client cannot lift, and no number of silent
//! or unauthenticated connections can keep the operator out.
//!
//! - **Header-read timeout** (`[api] header_timeout_ms`, 2 s): a request whose header has not
//!   arrived whole in time closes the connection (slowloris); hyper's own timer.
//! - **Idle timeout** (`[api] idle_timeout_ms`): no bytes in either direction for that long
//!   closes the connection. An event stream is never idle: it sends a keep-alive comment every
//!   15 s, or every third of the idle timeout when that is shorter (default 60 s).
//! - **Connection cap, counted per kind** (`[api] max_connections`): connections that are not
//!   event streams. Each is *waiting* (no request in flight: just connected, a header
//!   half-sent, idle between requests) or *busy* (a request in flight). At the cap, a new
//!   connection closes the one that has waited longest, so silent sockets only ever push each
//!   other out, and the operator's request, once sent, is never the one closed; only when
//!   every connection is busy is the new one answered `503` (one JSON answer, without reaching
//!   the router). An event stream leaves this count when it starts: streams have their own cap
//!   (`max_event_subscribers`, [`super::events`]), and need the token.
//! - **Refusals are logged at most once per 10 s**, with how many were not logged, so a flood
//!   does not flood the log too.
//!
//! axum's own `serve` has none of these. Stopping: the listener is dropped (no new
//! connections), every connection is asked to finish its request in flight, and
//! [`super::ApiServer::stop`] cuts what is left (event streams) after its grace period.

use std::collections::HashMap;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::Request;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Notify, watch};
use tokio::task::JoinSet;
use tower::ServiceExt;

/// The connection bounds of [`serve`].
#[derive(Debug, Clone, Copy)]
pub struct ConnectionLimits {
    pub max_connections: usize,
    pub header_timeout: Duration,
    pub idle_timeout: Duration,
}

/// What a connection is doing, for the cap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ConnState {
    /// No request in flight: may be closed to make room.
    Waiting,
    /// A request in flight.
    Busy,
    /// An event stream: outside the connection count.
    Stream,
}

#[derive(Debug)]
struct Conn {
    state: ConnState,
    since: Instant,
    close: Arc<Notify>,
}

/// The open connections and their states.
#[derive(Debug, Default)]
struct Registry {
    conns: Mutex<HashMap<u64, Conn>>,
    next: AtomicU64,
}

impl Registry {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<u64, Conn>> {
        self.conns.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Admits a connection under `max` (closing the longest-waiting one if need be); `None`
    /// if every counted connection is busy.
    fn admit(&self, max: usize) -> Option<(u64, Arc<Notify>)> {
        let mut conns = self.lock();
        let counted = conns
            .values()
            .filter(|c| c.state != ConnState::Stream)
            .count();
        if counted >= max {
            let oldest = conns
                .iter()
                .filter(|(_, c)| c.state == ConnState::Waiting)
                .min_by_key(|(_, c)| c.since)
                .map(|(id, _)| *id)?;
            if let Some(c) = conns.remove(&oldest) {
                c.close.notify_one();
            }
        }
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let close = Arc::new(Notify::new());
        conns.insert(
            id,
            Conn {
                state: ConnState::Waiting,
                since: Instant::now(),
                close: close.clone(),
            },
        );
        Some((id, close))
    }

    /// Closes the connection that has waited longest (out of file descriptors).
    fn close_oldest_waiting(&self) -> bool {
        let mut conns = self.lock();
        let oldest = conns
            .iter()
            .filter(|(_, c)| c.state == ConnState::Waiting)
            .min_by_key(|(_, c)| c.since)
            .map(|(id, _)| *id);
        match oldest.and_then(|id| conns.remove(&id)) {
            Some(c) => {
                c.close.notify_one();
                true
            }
            None => false,
        }
    }

    fn set(&self, id: u64, state: ConnState) {
        if let Some(c) = self.lock().get_mut(&id) {
            // A stream stays a stream until its connection ends.
            if c.state != ConnState::Stream {
                c.state = state;
                c.since = Instant::now();
            }
        }
    }

    fn remove(&self, id: u64) {
        self.lock().remove(&id);
    }
}

/// A request's connection, in its extensions: the event-stream handler marks it a stream, so
/// that it leaves the connection count ([`ConnectionLimits::max_connections`]).
#[derive(Debug, Clone)]
pub struct ConnectionHandle {
    id: u64,
    registry: Arc<Registry>,
}

impl ConnectionHandle {
    /// This connection is now an event stream: counted under `max_event_subscribers`, not
    /// `max_connections`, and never closed to make room.
    pub fn become_stream(&self) {
        self.registry.set(self.id, ConnState::Stream);
    }
}

/// A warning logged at most once per interval, with the count of those not logged.
#[derive(Debug)]
struct RateLimited {
    last: Mutex<Option<Instant>>,
    suppressed: AtomicU64,
    every: Duration,
}

impl RateLimited {
    fn new(every: Duration) -> RateLimited {
        RateLimited {
            last: Mutex::new(None),
            suppressed: AtomicU64::new(0),
            every,
        }
    }

    /// Whether to log now, and how many were not logged since the last time.
    fn check(&self) -> Option<u64> {
        let mut last = self.last.lock().unwrap_or_else(|p| p.into_inner());
        let now = Instant::now();
        if last.is_some_and(|t| now.duration_since(t) < self.every) {
            self.suppressed.fetch_add(1, Ordering::Relaxed);
            return None;
        }
        *last = Some(now);
        Some(self.suppressed.swap(0, Ordering::Relaxed))
    }
}

/// Serves `app` on `listener` until `stop` turns true.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnectionLimits,
    mut stop: watch::Receiver<bool>,
) {
    let registry = Arc::new(Registry::default());
    let refusals = RateLimited::new(Duration::from_secs(10));
    let mut connections = JoinSet::new();
    loop {
        while connections.try_join_next().is_some() {}
        let accepted = tokio::select! {
            _ = stop.wait_for(|s| *s) => break,
            a = listener.accept() => a,
        };
        let (stream, peer) = match accepted {
            Ok(a) => a,
            Err(e) => {
                // Out of file descriptors: make room by closing the connection that has waited
                // longest. Otherwise (a connection reset before accept) the listener itself is
                // fine: pause briefly instead of spinning, and go on.
                let out_of_fds = matches!(e.raw_os_error(), Some(libc::EMFILE | libc::ENFILE));
                if !(out_of_fds && registry.close_oldest_waiting()) {
                    if let Some(missed) = refusals.check() {
                        tracing::warn!(error = %e, missed, "accepting an API connection failed");
                    }
                    tokio::time::sleep(Duration::from_millis(50)).await;
                } else {
                    tokio::task::yield_now().await;
                }
                continue;
            }
        };
        match registry.admit(limits.max_connections) {
            Some((id, close)) => {
                let app = app.clone();
                let stop = stop.clone();
                let registry = registry.clone();
                connections.spawn(async move {
                    serve_connection(stream, app, limits, stop, id, close, registry.clone()).await;
                    registry.remove(id);
                });
            }
            None => {
                if let Some(missed) = refusals.check() {
                    tracing::warn!(%peer, max = limits.max_connections, missed,
                        "API connection refused: every connection has a request in flight");
                }
                connections.spawn(refuse_over_cap(stream, limits.max_connections));
            }
        }
    }
    drop(listener);
    while connections.join_next().await.is_some() {}
}

async fn serve_connection(
    stream: TcpStream,
    app: Router,
    limits: ConnectionLimits,
    mut stop: watch::Receiver<bool>,
    id: u64,
    close: Arc<Notify>,
    registry: Arc<Registry>,
) {
    let _ = stream.set_nodelay(true);
    let io = ActivityIo::new(stream);
    let activity = io.activity.clone();
    let handle = ConnectionHandle {
        id,
        registry: registry.clone(),
    };
    // Each request marks its connection busy until its answer's head is out, and carries the
    // handle for the event-stream handler.
    let service = tower::service_fn(move |mut request: Request<hyper::body::Incoming>| {
        let app = app.clone();
        let handle = handle.clone();
        async move {
            handle.registry.set(handle.id, ConnState::Busy);
            request.extensions_mut().insert(handle.clone());
            let response = app.oneshot(request.map(axum::body::Body::new)).await;
            handle.registry.set(handle.id, ConnState::Waiting);
            response
        }
    });
    let service = TowerToHyperService::new(service);
    let conn = hyper::server::conn::http1::Builder::new()
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout)
        .serve_connection(TokioIo::new(io), service);
    tokio::pin!(conn);
    let tick = (limits.idle_timeout / 4).max(Duration::from_millis(25));
    let mut stopping = false;
    loop {
        tokio::select! {
            r = conn.as_mut() => {
                if let Err(e) = r {
                    tracing::debug!(error = %e, "API connection ended with an error");
                }
                return;
            }
            _ = close.notified() => {
                tracing::debug!("closing a waiting API connection to make room for a new one");
                return;
            }
            _ = tokio::time::sleep(tick) => {
                if activity.idle_for() >= limits.idle_timeout {
                    tracing::debug!("closing an idle API connection");
                    return;
                }
            }
            _ = stop.wait_for(|s| *s), if !stopping => {
                stopping = true;
                conn.as_mut().graceful_shutdown();
            }
        }
    }
}

/// One 503 answer to a connection over the cap. The request is read first (briefly), so the
/// client sees the answer instead of a reset.
async fn refuse_over_cap(mut stream: TcpStream, max: usize) {
    let body = format!(
        "{{\"error\":\"the brdfd API has a request in flight on each of its {max} connections \
         ([api] max_connections); try again shortly\"}}"
    );
    let response = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\n\
         content-length: {}\r\nconnection: close\r\nretry-after: 1\r\n\r\n{body}",
        body.len()
    );
    let mut buf = [0u8; 8192];
    let _ = tokio::time::timeout(Duration::from_millis(200), stream.read(&mut buf)).await;
    let _ = tokio::time::timeout(Duration::from_secs(1), async {
        stream.write_all(response.as_bytes()).await?;
        stream.shutdown().await
    })
    .await;
}

/// Binds `addr` with a listen backlog of 4096 (the kernel caps it at `net.core.somaxconn`):
/// a burst of connections waits in the kernel's queue for the accept loop instead of having
/// its SYNs dropped (which costs a client a second before it tries again).
pub fn listen(addr: std::net::SocketAddr) -> std::io::Result<TcpListener> {
    let socket = if addr.is_ipv4() {
        tokio::net::TcpSocket::new_v4()?
    } else {
        tokio::net::TcpSocket::new_v6()?
    };
    socket.set_reuseaddr(true)?;
    socket.bind(addr)?;
    socket.listen(4096)
}

/// Raises this process's soft limit on open files to its hard limit (at most 65536), so that
/// the connection caps, not the descriptor limit, bound the API. Returns the limit now.
pub fn raise_fd_limit() -> u64 {
    // SAFETY: getrlimit/setrlimit on this process with a valid struct.
    unsafe {
        let mut lim = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) != 0 {
            return 0;
        }
        let want = lim.rlim_max.min(65_536);
        if lim.rlim_cur < want {
            lim.rlim_cur = want;
            libc::setrlimit(libc::RLIMIT_NOFILE, &lim);
        }
        lim.rlim_cur as u64
    }
}

/// When a connection last moved a byte, as milliseconds since its start.
#[derive(Debug)]
struct Activity {
    start: Instant,
    last_ms: AtomicU64,
}

impl Activity {
    fn touch(&self) {
        let ms = self.start.elapsed().as_millis() as u64;
        self.last_ms.store(ms, Ordering::Relaxed);
    }

    fn idle_for(&self) -> Duration {
        let now = self.start.elapsed().as_millis() as u64;
        Duration::from_millis(now.saturating_sub(self.last_ms.load(Ordering::Relaxed)))
    }
}

/// A TCP stream that records its last read or write.
struct ActivityIo {
    inner: TcpStream,
    activity: Arc<Activity>,
}

impl ActivityIo {
    fn new(inner: TcpStream) -> ActivityIo {
        ActivityIo {
            inner,
            activity: Arc::new(Activity {
                start: Instant::now(),
                last_ms: AtomicU64::new(0),
            }),
        }
    }
}

impl AsyncRead for ActivityIo {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        let r = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(r, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.activity.touch();
        }
        r
    }
}

impl AsyncWrite for ActivityIo {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write(cx, buf);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            self.activity.touch();
        }
        r
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn at_the_cap_the_longest_waiting_connection_makes_room() {
        let r = Registry::default();
        let (a, close_a) = r.admit(2).unwrap();
        let (b, _) = r.admit(2).unwrap();
        r.set(b, ConnState::Busy);
        // Full: the waiting one (a) is closed for the new one.
        let (c, _) = r.admit(2).unwrap();
        assert!(!r.lock().contains_key(&a));
        // close_a was notified: a stored permit completes at once.
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async {
            tokio::time::timeout(Duration::from_millis(100), close_a.notified())
                .await
                .expect("the closed connection was told");
        });
        // Both busy: refused.
        r.set(c, ConnState::Busy);
        assert!(r.admit(2).is_none());
        // A stream leaves the count.
        r.set(c, ConnState::Stream);
        assert!(r.admit(2).is_some());
        r.set(c, ConnState::Waiting);
        assert_eq!(
            r.lock()[&c].state,
            ConnState::Stream,
            "a stream stays a stream"
        );
    }

    #[test]
    fn refusals_are_logged_once_per_interval_with_the_count_missed() {
        let l = RateLimited::new(Duration::from_millis(50));
        assert_eq!(l.check(), Some(0));
        assert_eq!(l.check(), None);
        assert_eq!(l.check(), None);
        std::thread::sleep(Duration::from_millis(60));
        assert_eq!(l.check(), Some(2));
    }
}

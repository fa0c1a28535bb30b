//! Who may use the API: the bearer token, the Host and Origin checks and the JSON-only rule for
//! POST bodies, applied to every request by one middleware ([`guard`]) in front of every route.
//!
//! The threats, and which check stops each:
//! - **A web page the operator opens** (cross-site request forgery): it cannot send the token
//!   (browsers add `Authorization` only after a CORS preflight, which brdfd never grants), a
//!   foreign `Origin` or `Sec-Fetch-Site: cross-site` is refused with 403, and a POST whose body
//!   is not `application/json` (all a plain HTML form can send) is refused with 415.
//! - **DNS rebinding** (a page whose host name is re-pointed at 127.0.0.1): the browser sends
//!   the page's own name in `Host`; only loopback names and addresses and `[api] allowed_hosts`
//!   are answered, anything else gets 421.
//! - **Another local user or process**: it needs the token, which lives in a file readable only
//!   by the daemon's user (mode 0600; 0640 with the service's group under systemd).
//!
//! `GET /healthz` needs no token (monitoring probes); the Host check still applies to it.
//! The token is 256 random bits as 64 hex digits, created at the first start and compared in
//! constant time; it is never logged.
//!
//! **The operator's web page** ([`super::web`]) cannot hold the token: a page's script could
//! leak it. `brdfd open` (which has the token) asks for a one-time login ticket
//! (`POST /session/ticket`, bearer only) and prints `http://…/login?ticket=…`; opening it sets
//! a session cookie (`HttpOnly; SameSite=Strict`, [`Sessions`]) and the ticket is spent. A
//! request with that cookie and no `Authorization` header is let through like one with the
//! token, with two more checks: its `Sec-Fetch-Site` must be `same-origin` (or `none`, a typed
//! address), and a POST must carry the session's CSRF value in [`CSRF_HEADER`] — a custom
//! header, which no cross-origin page can add without a CORS preflight that brdfd never
//! grants. The page's own files (`/`, `/app.js`, `/app.css`) and `/login` need no credential;
//! they hold nothing secret.

use std::collections::HashMap;
use std::fs::OpenOptions;
use std::io::Write;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use hmac::{Hmac, Mac};
use rand::RngCore;
use sha2::{Digest, Sha256};

use super::ErrorBody;

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
    fn matches(&self, sent: &[u8]) -> bool {
        constant_time_eq(self.0.as_bytes(), sent)
    }
}

/// Whether two byte strings are equal, in time that depends only on their lengths.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Random hex names live in [`crate::names`] (the files brdfd writes use them too).
pub use crate::names::random_hex;

/// The web page's session cookie.
pub const SESSION_COOKIE: &str = "brdfd_session";
/// The header in which the page sends its session's CSRF value with every POST.
pub const CSRF_HEADER: &str = "x-brdfd-csrf";
/// How long a login ticket from `brdfd open` can be used (once).
pub const TICKET_LIFETIME: Duration = Duration::from_secs(120);
/// How long a session lasts before `brdfd open` is needed again.
pub const SESSION_LIFETIME: Duration = Duration::from_secs(12 * 3600);
/// Login tickets outstanding at once; the oldest is dropped beyond this.
const MAX_TICKETS: usize = 64;

/// The time sessions and tickets are judged by, in Unix milliseconds: the system clock, or a
/// clock a test moves ([`ManualClock`]).
pub trait Clock: Send + Sync {
    fn now_ms(&self) -> u64;
}

/// The system clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now_ms(&self) -> u64 {
        crate::store::now_ms().max(0) as u64
    }
}

/// A clock that moves only when told (tests of the lifetimes).
#[derive(Debug, Default)]
pub struct ManualClock(std::sync::atomic::AtomicU64);

impl ManualClock {
    pub fn at(ms: u64) -> ManualClock {
        ManualClock(std::sync::atomic::AtomicU64::new(ms))
    }

    pub fn advance(&self, by: Duration) {
        self.0
            .fetch_add(by.as_millis() as u64, std::sync::atomic::Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now_ms(&self) -> u64 {
        self.0.load(std::sync::atomic::Ordering::SeqCst)
    }
}

/// The web page's sessions: one-time login tickets (in memory, spent when used) and session
/// cookies. A cookie is `v1.EXPIRY.NONCE.MAC`, signed with HMAC-SHA-256 under a key derived
/// from the API token, so sessions outlive a daemon restart (the page reconnects by itself)
/// and end when the token is replaced. Logging out revokes the cookie until it would have
/// expired anyway; with a revocation file ([`Sessions::with_revocation_file`]: `brdfd serve`
/// keeps `brdfd.sessions` beside the token) the revocation survives a restart too.
pub struct Sessions {
    key: [u8; 32],
    clock: Arc<dyn Clock>,
    /// Ticket → its expiry, Unix ms.
    tickets: Mutex<HashMap<String, u64>>,
    /// Revoked cookie → its expiry, Unix s.
    revoked: Mutex<HashMap<String, u64>>,
    revocation_file: Option<PathBuf>,
}

impl std::fmt::Debug for Sessions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Sessions(…)")
    }
}

/// Why the revocation file could not be read or written at start.
#[derive(Debug, thiserror::Error)]
#[error(
    "cannot use the web sessions' revocation file {path}: {source}; it must be a regular file \
     of brdfd's user (delete it to start afresh: sessions ended before are then accepted again \
     until they expire)"
)]
pub struct RevocationFileError {
    path: PathBuf,
    #[source]
    source: std::io::Error,
}

impl Sessions {
    /// Sessions signed under a key derived from `token`, on the system clock.
    pub fn new(token: &Token) -> Sessions {
        Sessions::with_clock(token, Arc::new(SystemClock))
    }

    /// Sessions on a given clock.
    pub fn with_clock(token: &Token, clock: Arc<dyn Clock>) -> Sessions {
        let mut h = Sha256::new();
        h.update(b"brdfd web session key v1\0");
        h.update(token.as_str().as_bytes());
        Sessions {
            key: h.finalize().into(),
            clock,
            tickets: Mutex::new(HashMap::new()),
            revoked: Mutex::new(HashMap::new()),
            revocation_file: None,
        }
    }

    /// Keeps logouts in `path` (one cookie a line, appended and synced at logout) and reads
    /// those still unexpired. The file is created private (0600) and rewritten without the
    /// expired ones.
    pub fn with_revocation_file(mut self, path: &Path) -> Result<Sessions, RevocationFileError> {
        use std::io::Read;
        use std::os::unix::fs::OpenOptionsExt;
        let err = |source| RevocationFileError {
            path: path.to_path_buf(),
            source,
        };
        crate::safe_fs::protect(path, "the web sessions' revocation file");
        let now = self.now_s();
        let mut text = String::new();
        match OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
            .open(path)
        {
            Ok(f) => {
                if !f.metadata().map_err(err)?.is_file() {
                    return Err(err(std::io::Error::other("not a regular file")));
                }
                // A few thousand logouts in 12 h at most; 16 MiB is far beyond that.
                f.take(16 << 20).read_to_string(&mut text).map_err(err)?;
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(err(e)),
        }
        let kept: HashMap<String, u64> = text
            .lines()
            .filter_map(|l| {
                let c = l.trim();
                let e = Sessions::expires_at_ms(c)? / 1000;
                (e > now).then(|| (c.to_string(), e))
            })
            .collect();
        // Rewritten without the expired: a new private file renamed over the old one.
        let mut tmp = path.as_os_str().to_os_string();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        let _ = std::fs::remove_file(&tmp);
        let mut f = OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(crate::safe_fs::private_mode())
            .custom_flags(libc::O_NOFOLLOW)
            .open(&tmp)
            .map_err(err)?;
        for c in kept.keys() {
            writeln!(f, "{c}").map_err(err)?;
        }
        f.sync_all().map_err(err)?;
        std::fs::rename(&tmp, path).map_err(err)?;
        self.revoked = Mutex::new(kept);
        self.revocation_file = Some(path.to_path_buf());
        Ok(self)
    }

    fn now_s(&self) -> u64 {
        self.clock.now_ms() / 1000
    }

    fn mac(&self, what: &[u8]) -> String {
        let mut m = <Hmac<Sha256> as Mac>::new_from_slice(&self.key)
            .expect("HMAC takes a key of any length");
        m.update(what);
        hex::encode(&m.finalize().into_bytes())
    }

    /// A new one-time login ticket (256 random bits in hex), valid for [`TICKET_LIFETIME`].
    pub fn issue_ticket(&self) -> String {
        let mut bytes = [0u8; 32];
        rand::rng().fill_bytes(&mut bytes);
        let ticket = hex::encode(&bytes);
        let now = self.clock.now_ms();
        let mut tickets = self.tickets.lock().unwrap_or_else(|p| p.into_inner());
        tickets.retain(|_, expires| *expires > now);
        if tickets.len() >= MAX_TICKETS
            && let Some(oldest) = tickets
                .iter()
                .min_by_key(|(_, e)| **e)
                .map(|(t, _)| t.clone())
        {
            tickets.remove(&oldest);
        }
        tickets.insert(ticket.clone(), now + TICKET_LIFETIME.as_millis() as u64);
        ticket
    }

    /// Spends a ticket: a new session cookie value if the ticket was issued, unused and
    /// unexpired; `None` otherwise.
    pub fn redeem(&self, ticket: &str) -> Option<String> {
        let mut tickets = self.tickets.lock().unwrap_or_else(|p| p.into_inner());
        // Look the ticket up by constant-time comparison: no timing hint about its digits.
        let key = tickets
            .keys()
            .find(|t| constant_time_eq(t.as_bytes(), ticket.as_bytes()))
            .cloned()?;
        let expires = tickets.remove(&key)?;
        (expires > self.clock.now_ms()).then(|| self.new_session(self.now_s()))
    }

    fn new_session(&self, now: u64) -> String {
        let mut nonce = [0u8; 16];
        rand::rng().fill_bytes(&mut nonce);
        let body = format!(
            "v1.{}.{}",
            now + SESSION_LIFETIME.as_secs(),
            hex::encode(&nonce)
        );
        let mac = self.mac(body.as_bytes());
        format!("{body}.{mac}")
    }

    /// Whether a cookie value is a session this daemon signed, unexpired and not logged out.
    pub fn verify(&self, cookie: &str) -> bool {
        self.verify_at(cookie, self.now_s())
    }

    fn verify_at(&self, cookie: &str, now: u64) -> bool {
        let Some((body, mac)) = cookie.rsplit_once('.') else {
            return false;
        };
        let mut parts = body.split('.');
        let (Some("v1"), Some(expiry), Some(nonce), None) =
            (parts.next(), parts.next(), parts.next(), parts.next())
        else {
            return false;
        };
        if nonce.len() != 32
            || !constant_time_eq(self.mac(body.as_bytes()).as_bytes(), mac.as_bytes())
        {
            return false;
        }
        let unexpired = expiry.parse::<u64>().is_ok_and(|e| e > now);
        unexpired
            && !self
                .revoked
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .contains_key(cookie)
    }

    /// When a (verified) session ends, in Unix milliseconds.
    pub fn expires_at_ms(cookie: &str) -> Option<u64> {
        cookie
            .split('.')
            .nth(1)?
            .parse::<u64>()
            .ok()
            .map(|s| s * 1000)
    }

    /// The CSRF value of a session: the page sends it in [`CSRF_HEADER`] with every POST.
    pub fn csrf(&self, cookie: &str) -> String {
        self.mac(format!("csrf:{cookie}").as_bytes())
    }

    /// Ends a session (logout): refused from now on and, with a revocation file, after a
    /// restart too (the line is on disk before this returns).
    pub fn revoke(&self, cookie: &str) {
        let now = self.now_s();
        // Only a live cookie this daemon signed is recorded (any other is refused anyway), so
        // nobody without a session can grow the file.
        if !self.verify(cookie) {
            return;
        }
        let Some(expiry) = Sessions::expires_at_ms(cookie).map(|e| e / 1000) else {
            return;
        };
        let mut revoked = self.revoked.lock().unwrap_or_else(|p| p.into_inner());
        // Expired cookies are refused anyway: forget them.
        revoked.retain(|_, e| *e > now);
        revoked.insert(cookie.to_string(), expiry);
        if let Some(path) = &self.revocation_file {
            use std::os::unix::fs::OpenOptionsExt;
            let written = OpenOptions::new()
                .append(true)
                .custom_flags(libc::O_NOFOLLOW)
                .open(path)
                .and_then(|mut f| {
                    writeln!(f, "{cookie}")?;
                    f.sync_all()
                });
            if let Err(e) = written {
                tracing::error!(error = %e, file = %path.display(),
                    "cannot record a logout: the session ends now, but a restart would accept it again");
            }
        }
    }
}

/// The value of the session cookie in a request, if it sent one.
pub fn session_cookie(headers: &HeaderMap) -> Option<&str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .find_map(|pair| {
            let (name, value) = pair.trim().split_once('=')?;
            (name == SESSION_COOKIE).then_some(value.trim())
        })
}

/// What the guard lets through.
#[derive(Debug, Clone)]
pub struct Access {
    token: Token,
    /// The web page's sessions, signed under a key derived from the token.
    sessions: Arc<Sessions>,
    /// Where the token is, for the 401 message.
    token_file: Option<PathBuf>,
    /// Lower-case host names (no port) answered besides the loopback ones.
    allowed_hosts: Vec<String>,
}

impl Access {
    pub fn new(token: Token) -> Access {
        Access {
            sessions: Arc::new(Sessions::new(&token)),
            token,
            token_file: None,
            allowed_hosts: Vec::new(),
        }
    }

    /// Names the token file (its name only, never its folder) in the 401 message.
    pub fn with_token_file(mut self, path: impl Into<PathBuf>) -> Access {
        self.token_file = Some(path.into());
        self
    }

    /// The web page's sessions with their logouts kept in `path` across restarts.
    pub fn with_revocation_file(mut self, path: &Path) -> Result<Access, RevocationFileError> {
        let sessions = Sessions::new(&self.token).with_revocation_file(path)?;
        self.sessions = Arc::new(sessions);
        Ok(self)
    }

    /// The web page's sessions on another clock (tests of the lifetimes).
    pub fn with_clock(mut self, clock: Arc<dyn Clock>) -> Access {
        self.sessions = Arc::new(Sessions::with_clock(&self.token, clock));
        self
    }

    /// Host names answered besides loopback (`[api] allowed_hosts`).
    pub fn with_allowed_hosts(mut self, hosts: impl IntoIterator<Item = String>) -> Access {
        self.allowed_hosts = hosts.into_iter().map(|h| h.to_ascii_lowercase()).collect();
        self
    }

    pub fn token(&self) -> &Token {
        &self.token
    }

    /// The web page's sessions.
    pub fn sessions(&self) -> &Sessions {
        &self.sessions
    }

    /// Whether `host` (a Host header's host part, or an Origin's) is one the API answers to.
    fn host_allowed(&self, host: &str) -> bool {
        let host = host.to_ascii_lowercase();
        if host == "localhost" || host.ends_with(".localhost") {
            return true;
        }
        let bare = host.trim_start_matches('[').trim_end_matches(']');
        if let Ok(ip) = bare.parse::<IpAddr>()
            && ip.is_loopback()
        {
            return true;
        }
        self.allowed_hosts.contains(&host)
    }
}

/// Splits `host[:port]` (with `[v6]` brackets) into the host and the port, if any.
fn split_host_port(authority: &str) -> (&str, Option<&str>) {
    if authority.starts_with('[') {
        match authority.find(']') {
            Some(end) => {
                let rest = &authority[end + 1..];
                (&authority[..=end], rest.strip_prefix(':'))
            }
            None => (authority, None),
        }
    } else {
        match authority.rsplit_once(':') {
            Some((h, p)) if !h.contains(':') => (h, Some(p)),
            _ => (authority, None),
        }
    }
}

fn refuse(status: StatusCode, message: String) -> Response {
    let mut r = (status, axum::Json(ErrorBody::message(message))).into_response();
    if status == StatusCode::UNAUTHORIZED {
        r.headers_mut()
            .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
    }
    r
}

fn header_str(headers: &HeaderMap, name: header::HeaderName) -> Option<&str> {
    headers.get(name).and_then(|v| v.to_str().ok())
}

/// The media type of an X-Rite `.xlsx` export, which `POST /scans/import` takes.
pub const XLSX_MEDIA_TYPE: &str =
    "application/vnd.openxmlformats-officedocument.spreadsheetml.sheet";

/// The checks, in order: Host (421), Origin and fetch metadata (403), token (401), POST body
/// type (415). Each refusal says what to do.
pub async fn guard(State(access): State<Arc<Access>>, request: Request, next: Next) -> Response {
    // A body promised larger than any request may be is refused before a byte of it is read,
    // and the connection closed.
    // `POST /scans/import` also takes an instrument export (an X-Rite .xlsx, a few MiB).
    let limit = if request.uri().path() == "/scans/import" {
        super::MAX_IMPORT_BODY_BYTES
    } else {
        super::MAX_BODY_BYTES
    };
    if let Some(len) = header_str(request.headers(), header::CONTENT_LENGTH)
        .and_then(|v| v.trim().parse::<u64>().ok())
        && len > limit as u64
    {
        let mut r = refuse(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!(
                "the request body is {len} bytes, over the limit of {limit} bytes (a brdfd.scan/1 \
                 file is about 30 KiB, an X-Rite .xlsx export a few MiB)"
            ),
        );
        r.headers_mut()
            .insert(header::CONNECTION, HeaderValue::from_static("close"));
        return r;
    }
    if let Err(response) = check(
        &access,
        request.method(),
        request.uri().path(),
        request.headers(),
    ) {
        return response;
    }
    next.run(request).await
}

/// Paths a GET may fetch with no credential: the health probe, the web page's own files, the
/// login link (which needs its one-time ticket instead) and `/session`, which answers whether
/// the request carries a session (and only then its CSRF value).
pub const OPEN_PATHS: [&str; 6] = ["/healthz", "/", "/app.js", "/app.css", "/login", "/session"];

/// Minting login tickets needs the token itself: a page's session cannot make new sessions.
pub const TICKET_PATH: &str = "/session/ticket";

/// Whether a request's fetch metadata says it comes from the daemon's own page (or from no
/// page: a typed address, a tool that sends no `Sec-Fetch-Site`).
pub fn from_own_page(headers: &HeaderMap) -> bool {
    header_str(headers, header::HeaderName::from_static("sec-fetch-site")).is_none_or(|site| {
        site.eq_ignore_ascii_case("same-origin") || site.eq_ignore_ascii_case("none")
    })
}

/// The checks on a request that carries a valid session cookie instead of the token: it comes
/// from the page itself (fetch metadata), and a POST carries the session's CSRF value.
fn check_page_request(
    access: &Access,
    method: &Method,
    headers: &HeaderMap,
    cookie: &str,
) -> Result<(), Response> {
    if !from_own_page(headers) {
        return Err(refuse(
            StatusCode::FORBIDDEN,
            "the session cookie is accepted only from brdfd's own page (this request is \
             cross-origin)"
                .into(),
        ));
    }
    if method != Method::GET && method != Method::HEAD {
        let sent = header_str(headers, header::HeaderName::from_static(CSRF_HEADER));
        if !sent.is_some_and(|c| {
            constant_time_eq(c.as_bytes(), access.sessions.csrf(cookie).as_bytes())
        }) {
            return Err(refuse(
                StatusCode::FORBIDDEN,
                format!(
                    "a request from the web page must carry its {CSRF_HEADER} header: reload \
                     the page"
                ),
            ));
        }
    }
    Ok(())
}

fn check(
    access: &Access,
    method: &Method,
    path: &str,
    headers: &HeaderMap,
) -> Result<(), Response> {
    let Some(host) = header_str(headers, header::HOST) else {
        return Err(refuse(
            StatusCode::BAD_REQUEST,
            "the request has no Host header (HTTP/1.1 requires one)".into(),
        ));
    };
    let (host_name, _) = split_host_port(host);
    if !access.host_allowed(host_name) {
        return Err(refuse(
            StatusCode::MISDIRECTED_REQUEST,
            format!(
                "this brdfd daemon does not answer to the host name \"{}\": use 127.0.0.1 or \
                 localhost, or add the name to [api] allowed_hosts",
                host_name.escape_debug()
            ),
        ));
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let allowed = origin.to_str().ok().is_some_and(|o| {
            let rest = o
                .strip_prefix("http://")
                .or_else(|| o.strip_prefix("https://"));
            // Same origin only: the origin's host and port must be those the request was sent
            // to (the daemon's own page), and the host one the API answers to.
            rest.is_some_and(|authority| {
                authority.eq_ignore_ascii_case(host)
                    && access.host_allowed(split_host_port(authority).0)
            })
        });
        if !allowed {
            return Err(refuse(
                StatusCode::FORBIDDEN,
                format!(
                    "requests from the web page at {:?} are not accepted: the brdfd API answers \
                     only its own page and the operator commands",
                    origin
                ),
            ));
        }
    }
    if header_str(headers, header::HeaderName::from_static("sec-fetch-site"))
        .is_some_and(|s| s.eq_ignore_ascii_case("cross-site"))
    {
        return Err(refuse(
            StatusCode::FORBIDDEN,
            "cross-site requests are not accepted".into(),
        ));
    }
    let open = method == Method::GET && OPEN_PATHS.contains(&path);
    if !open {
        let sent = header_str(headers, header::AUTHORIZATION)
            .and_then(|v| v.strip_prefix("Bearer "))
            .map(str::trim);
        let cookie = session_cookie(headers).filter(|_| sent.is_none());
        if let Some(cookie) = cookie
            && path != TICKET_PATH
            && access.sessions.verify(cookie)
        {
            check_page_request(access, method, headers, cookie)?;
        } else if !sent.is_some_and(|t| access.token.matches(t.as_bytes())) {
            // The file's name only: an absolute path tells a stranger about the machine.
            let where_ = access
                .token_file
                .as_ref()
                .and_then(|p| p.file_name())
                .map(|n| {
                    format!(
                        " (the token is in the daemon's {} file, [api] token_file)",
                        n.to_string_lossy()
                    )
                })
                .unwrap_or_default();
            if cookie.is_some() && path != TICKET_PATH {
                return Err(refuse(
                    StatusCode::UNAUTHORIZED,
                    "the web page's session has expired or was ended: run `brdfd open` on the \
                     lab PC for a new login link"
                        .into(),
                ));
            }
            let what = if sent.is_some() {
                "the API token sent is not this daemon's"
            } else {
                "this request needs the API token"
            };
            return Err(refuse(
                StatusCode::UNAUTHORIZED,
                format!(
                    "{what}: send `Authorization: Bearer <token>`{where_}; the operator \
                     commands read it from --token-file, BRDFD_TOKEN or the configuration \
                     (for the web page, run `brdfd open`)"
                ),
            ));
        }
    }
    if method == Method::POST {
        // JSON, or an X-Rite .xlsx to `POST /scans/import`: neither is a type a plain HTML
        // form can send, and a script needs a CORS preflight for them, which brdfd never grants.
        let allowed = |m: &str| {
            m.eq_ignore_ascii_case("application/json")
                || (path == "/scans/import" && m.eq_ignore_ascii_case(XLSX_MEDIA_TYPE))
        };
        let json = header_str(headers, header::CONTENT_TYPE)
            .is_some_and(|ct| ct.split(';').next().is_some_and(|m| allowed(m.trim())));
        if !json {
            return Err(refuse(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "POST bodies must be JSON: send `Content-Type: application/json` (an empty body \
                 is fine where none is needed)"
                    .into(),
            ));
        }
    }
    Ok(())
}

/// An empty body with the guard's answer, for tests of [`check`] without a server.
#[cfg(test)]
pub(crate) fn check_for_test(
    access: &Access,
    method: &Method,
    path: &str,
    headers: &HeaderMap,
) -> StatusCode {
    match check(access, method, path, headers) {
        Ok(()) => StatusCode::OK,
        Err(r) => r.status(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(pairs: &[(&str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.insert(
                header::HeaderName::from_bytes(k.as_bytes()).unwrap(),
                HeaderValue::from_str(v).unwrap(),
            );
        }
        h
    }

    fn access() -> (Access, String) {
        let t = Token::generate();
        let s = t.as_str().to_string();
        (
            Access::new(t).with_allowed_hosts(["lab-pc.example".to_string()]),
            s,
        )
    }

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
    fn every_check_refuses_with_its_status() {
        let (a, token) = access();
        let bearer = format!("Bearer {token}");
        let ok = [
            ("host", "127.0.0.1:7878"),
            ("authorization", bearer.as_str()),
        ];
        let get =
            |h: &[(&str, &str)], path: &str| check_for_test(&a, &Method::GET, path, &headers(h));
        let post =
            |h: &[(&str, &str)]| check_for_test(&a, &Method::POST, "/reference", &headers(h));
        assert_eq!(get(&ok, "/scans"), StatusCode::OK);
        for host in [
            "localhost:1",
            "[::1]:7878",
            "127.0.0.2",
            "lab-pc.example:80",
            "LOCALHOST",
        ] {
            assert_eq!(
                get(&[("host", host), ok[1]], "/scans"),
                StatusCode::OK,
                "{host}"
            );
        }
        // Host: DNS rebinding.
        for host in [
            "attacker.example",
            "attacker.example:7878",
            "127.0.0.1.nip.io",
            "10.0.0.1",
        ] {
            assert_eq!(
                get(&[("host", host), ok[1]], "/scans"),
                StatusCode::MISDIRECTED_REQUEST,
                "{host}"
            );
        }
        assert_eq!(get(&[ok[1]], "/scans"), StatusCode::BAD_REQUEST);
        // Token.
        assert_eq!(get(&[ok[0]], "/scans"), StatusCode::UNAUTHORIZED);
        assert_eq!(
            get(&[ok[0], ("authorization", "Bearer 00")], "/scans"),
            StatusCode::UNAUTHORIZED
        );
        let mut wrong = token.clone().into_bytes();
        wrong[63] = if wrong[63] == b'0' { b'1' } else { b'0' };
        let wrong = format!("Bearer {}", String::from_utf8(wrong).unwrap());
        assert_eq!(
            get(&[ok[0], ("authorization", &wrong)], "/scans"),
            StatusCode::UNAUTHORIZED
        );
        assert_eq!(get(&[ok[0]], "/healthz"), StatusCode::OK);
        assert_eq!(
            get(&[("host", "evil.example")], "/healthz"),
            StatusCode::MISDIRECTED_REQUEST
        );
        // Origin and fetch metadata.
        let same = [ok[0], ok[1], ("origin", "http://127.0.0.1:7878")];
        assert_eq!(get(&same, "/scans"), StatusCode::OK);
        for origin in [
            "https://evil.example",
            "null",
            "http://127.0.0.1:9999",
            "http://localhost:7878",
        ] {
            assert_eq!(
                get(&[ok[0], ok[1], ("origin", origin)], "/scans"),
                StatusCode::FORBIDDEN,
                "{origin}"
            );
        }
        assert_eq!(
            get(&[ok[0], ok[1], ("sec-fetch-site", "cross-site")], "/scans"),
            StatusCode::FORBIDDEN
        );
        // POST bodies.
        assert_eq!(post(&ok), StatusCode::UNSUPPORTED_MEDIA_TYPE);
        assert_eq!(
            post(&[ok[0], ok[1], ("content-type", "text/plain")]),
            StatusCode::UNSUPPORTED_MEDIA_TYPE
        );
        assert_eq!(
            post(&[
                ok[0],
                ok[1],
                ("content-type", "application/x-www-form-urlencoded")
            ]),
            StatusCode::UNSUPPORTED_MEDIA_TYPE
        );
        assert_eq!(
            post(&[
                ok[0],
                ok[1],
                ("content-type", "application/json; charset=utf-8")
            ]),
            StatusCode::OK
        );
        // The token is checked before the body type: no hint to a caller without it.
        assert_eq!(
            post(&[ok[0], ("content-type", "text/plain")]),
            StatusCode::UNAUTHORIZED
        );
    }

    #[test]
    fn a_ticket_opens_one_session_once_and_sessions_are_signed() {
        let token = Token::generate();
        let sessions = Sessions::new(&token);
        let ticket = sessions.issue_ticket();
        assert_eq!(ticket.len(), 64);
        assert!(sessions.redeem("not-a-ticket").is_none());
        let cookie = sessions
            .redeem(&ticket)
            .expect("a fresh ticket opens a session");
        assert!(sessions.redeem(&ticket).is_none(), "a ticket works once");
        assert!(sessions.verify(&cookie));
        // Another daemon's token (or a replaced one) does not accept it.
        assert!(!Sessions::new(&Token::generate()).verify(&cookie));
        // Any change breaks the signature; a later expiry cannot be forged.
        let (body, mac) = cookie.rsplit_once('.').unwrap();
        let mut flipped = mac.to_string().into_bytes();
        flipped[0] = if flipped[0] == b'0' { b'1' } else { b'0' };
        assert!(!sessions.verify(&format!("{body}.{}", String::from_utf8(flipped).unwrap())));
        let parts: Vec<&str> = body.split('.').collect();
        let later = format!(
            "v1.{}.{}.{mac}",
            parts[1].parse::<u64>().unwrap() + 1,
            parts[2]
        );
        assert!(!sessions.verify(&later));
        assert!(!sessions.verify(""));
        assert!(!sessions.verify("v1.1.2.3.4"));
        // It expires.
        let expiry: u64 = parts[1].parse().unwrap();
        assert!(sessions.verify_at(&cookie, expiry - 1));
        assert!(!sessions.verify_at(&cookie, expiry));
        // The CSRF value is the session's own, and logging out ends the session.
        let other = sessions.redeem(&sessions.issue_ticket()).unwrap();
        assert_ne!(sessions.csrf(&cookie), sessions.csrf(&other));
        sessions.revoke(&cookie);
        assert!(!sessions.verify(&cookie));
        assert!(sessions.verify(&other));
    }

    #[test]
    fn tickets_last_two_minutes_and_sessions_twelve_hours_on_the_clock() {
        let clock = Arc::new(ManualClock::at(1_800_000_000_000));
        let sessions = Sessions::with_clock(&Token::generate(), clock.clone());
        // A ticket works until its two minutes are over, not after.
        let early = sessions.issue_ticket();
        let late = sessions.issue_ticket();
        clock.advance(TICKET_LIFETIME - Duration::from_millis(1));
        let cookie = sessions
            .redeem(&early)
            .expect("a ticket just inside its lifetime");
        clock.advance(Duration::from_millis(1));
        assert!(sessions.redeem(&late).is_none(), "a ticket at its lifetime");
        // The session from it lasts twelve hours from then.
        assert!(sessions.verify(&cookie));
        clock.advance(SESSION_LIFETIME - Duration::from_secs(2));
        assert!(
            sessions.verify(&cookie),
            "a session just inside its lifetime"
        );
        clock.advance(Duration::from_secs(2));
        assert!(!sessions.verify(&cookie), "a session past its lifetime");
        assert_eq!(TICKET_LIFETIME, Duration::from_secs(120));
        assert_eq!(SESSION_LIFETIME, Duration::from_secs(12 * 3600));
    }

    #[test]
    fn a_logout_survives_a_restart_with_the_revocation_file() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("brdfd.db.sessions");
        let token = Token::generate();
        let clock = Arc::new(ManualClock::at(1_800_000_000_000));
        let first = Sessions::with_clock(&token, clock.clone())
            .with_revocation_file(&file)
            .unwrap();
        let ended = first.redeem(&first.issue_ticket()).unwrap();
        let kept = first.redeem(&first.issue_ticket()).unwrap();
        first.revoke(&ended);
        // A forged cookie is not recorded.
        first.revoke(&format!(
            "v1.99999999999.{}.{}",
            "0".repeat(32),
            "0".repeat(64)
        ));
        drop(first);
        let mode = std::fs::metadata(&file).unwrap().permissions().mode();
        assert_eq!(mode & 0o077 & !0o040, 0, "{mode:o}");
        assert_eq!(std::fs::read_to_string(&file).unwrap().lines().count(), 1);
        // The next daemon, same token: the ended session stays ended, the other goes on.
        let second = Sessions::with_clock(&token, clock.clone())
            .with_revocation_file(&file)
            .unwrap();
        assert!(!second.verify(&ended));
        assert!(second.verify(&kept));
        // Without the file (the old behaviour) the restart would have let it back in.
        assert!(Sessions::with_clock(&token, clock.clone()).verify(&ended));
        // Once expired, the line is dropped at the next start.
        clock.advance(SESSION_LIFETIME);
        let _third = Sessions::with_clock(&token, clock)
            .with_revocation_file(&file)
            .unwrap();
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "");
        // A FIFO (or anything but a regular file) is refused, without hanging.
        let fifo = dir.path().join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        assert!(Sessions::new(&token).with_revocation_file(&fifo).is_err());
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

    #[test]
    fn a_401_names_the_token_file_but_not_its_folder() {
        let t = Token::generate();
        let a = Access::new(t).with_token_file("/var/lib/brdfd/brdfd.token");
        let r = check(
            &a,
            &Method::GET,
            "/scans",
            &headers(&[("host", "127.0.0.1:7878")]),
        )
        .unwrap_err();
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        let body =
            rt.block_on(async { axum::body::to_bytes(r.into_body(), 1 << 16).await.unwrap() });
        let body = String::from_utf8_lossy(&body);
        assert!(body.contains("brdfd.token"), "{body}");
        assert!(!body.contains("/var/lib"), "{body}");
    }

    #[test]
    fn a_session_cookie_is_accepted_only_from_the_page_and_with_its_csrf_value() {
        let (a, token) = access();
        let cookie = a.sessions().redeem(&a.sessions().issue_ticket()).unwrap();
        let jar = format!("other=1; {SESSION_COOKIE}={cookie}");
        let csrf = a.sessions().csrf(&cookie);
        let host = ("host", "127.0.0.1:7878");
        let json = ("content-type", "application/json");
        let own = ("sec-fetch-site", "same-origin");
        let run = |method: &Method, path: &str, h: &[(&str, &str)]| {
            check_for_test(&a, method, path, &headers(h))
        };
        assert_eq!(
            run(&Method::GET, "/status", &[host, ("cookie", &jar), own]),
            StatusCode::OK
        );
        assert_eq!(
            run(&Method::GET, "/status", &[host, ("cookie", &jar)]),
            StatusCode::OK
        );
        // From another site or another origin of the same site (another loopback port).
        for site in ["same-site", "cross-site"] {
            assert_eq!(
                run(
                    &Method::GET,
                    "/status",
                    &[host, ("cookie", &jar), ("sec-fetch-site", site)]
                ),
                StatusCode::FORBIDDEN,
                "{site}"
            );
        }
        // A POST needs the CSRF header with the session's value.
        assert_eq!(
            run(
                &Method::POST,
                "/reference",
                &[host, ("cookie", &jar), own, json]
            ),
            StatusCode::FORBIDDEN
        );
        assert_eq!(
            run(
                &Method::POST,
                "/reference",
                &[
                    host,
                    ("cookie", &jar),
                    own,
                    json,
                    (CSRF_HEADER, "0".repeat(64).as_str())
                ]
            ),
            StatusCode::FORBIDDEN
        );
        assert_eq!(
            run(
                &Method::POST,
                "/reference",
                &[
                    host,
                    ("cookie", &jar),
                    own,
                    json,
                    (CSRF_HEADER, csrf.as_str())
                ]
            ),
            StatusCode::OK
        );
        // A form post (no JSON) is still refused even with the CSRF value.
        assert_eq!(
            run(
                &Method::POST,
                "/reference",
                &[host, ("cookie", &jar), own, (CSRF_HEADER, csrf.as_str())]
            ),
            StatusCode::UNSUPPORTED_MEDIA_TYPE
        );
        // A session cannot mint login tickets; the token can.
        assert_eq!(
            run(
                &Method::POST,
                TICKET_PATH,
                &[
                    host,
                    ("cookie", &jar),
                    own,
                    json,
                    (CSRF_HEADER, csrf.as_str())
                ]
            ),
            StatusCode::UNAUTHORIZED
        );
        let bearer = format!("Bearer {token}");
        assert_eq!(
            run(
                &Method::POST,
                TICKET_PATH,
                &[host, ("authorization", &bearer), json]
            ),
            StatusCode::OK
        );
        // A forged or ended session is a 401; the page's files and /session stay open.
        let forged = format!(
            "{SESSION_COOKIE}=v1.99999999999.{}.{}",
            "0".repeat(32),
            "0".repeat(64)
        );
        assert_eq!(
            run(&Method::GET, "/status", &[host, ("cookie", &forged)]),
            StatusCode::UNAUTHORIZED
        );
        for path in ["/", "/app.js", "/app.css", "/login", "/session"] {
            assert_eq!(run(&Method::GET, path, &[host]), StatusCode::OK, "{path}");
        }
        // The Host check still applies to them (DNS rebinding).
        assert_eq!(
            run(&Method::GET, "/", &[("host", "evil.example")]),
            StatusCode::MISDIRECTED_REQUEST
        );
    }
}

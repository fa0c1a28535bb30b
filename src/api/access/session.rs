//! The web page's sessions: one-time login tickets, signed session cookies with their CSRF
//! values, logouts (kept across restarts in a revocation file) and the clock they are judged by.

use std::collections::HashMap;
use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::http::{HeaderMap, header};
use hmac::{Hmac, Mac};
use rand::RngCore;
use sha2::{Digest, Sha256};

use super::token::{Token, constant_time_eq};

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

#[cfg(test)]
mod tests {
    use super::*;

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
}

//! Who may use the API: the bearer token, the Host and Origin checks and the JSON-only rule for
//! POST bodies, applied to every request by one middleware ([`guard()`]) in front of every route.
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

mod guard;
mod session;
mod token;

pub use guard::{Access, OPEN_PATHS, TICKET_PATH, XLSX_MEDIA_TYPE, from_own_page, guard};
pub use session::{
    CSRF_HEADER, Clock, ManualClock, RevocationFileError, SESSION_COOKIE, SESSION_LIFETIME,
    Sessions, SystemClock, TICKET_LIFETIME, session_cookie,
};
pub use token::{Token, TokenError};

/// Random hex names live in [`crate::names`] (the files brdfd writes use them too).
pub use crate::names::random_hex;

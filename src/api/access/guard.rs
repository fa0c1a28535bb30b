//! The middleware in front of every route: the body size limit, then the Host, Origin and
//! fetch-metadata checks, the token or session, and the POST body type.

use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::session::{CSRF_HEADER, Clock, RevocationFileError, Sessions, session_cookie};
use super::token::{Token, constant_time_eq};
use crate::api::ErrorBody;

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
        crate::api::MAX_IMPORT_BODY_BYTES
    } else {
        crate::api::MAX_BODY_BYTES
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
    use crate::api::access::SESSION_COOKIE;

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
        let session = ("cookie", jar.as_str());
        let with_csrf = (CSRF_HEADER, csrf.as_str());
        let run = |method: &Method, path: &str, h: &[(&str, &str)]| {
            check_for_test(&a, method, path, &headers(h))
        };
        assert_eq!(
            run(&Method::GET, "/status", &[host, session, own]),
            StatusCode::OK
        );
        assert_eq!(
            run(&Method::GET, "/status", &[host, session]),
            StatusCode::OK
        );
        // From another site or another origin of the same site (another loopback port).
        for site in ["same-site", "cross-site"] {
            assert_eq!(
                run(
                    &Method::GET,
                    "/status",
                    &[host, session, ("sec-fetch-site", site)]
                ),
                StatusCode::FORBIDDEN,
                "{site}"
            );
        }
        // A POST needs the CSRF header with the session's value.
        assert_eq!(
            run(&Method::POST, "/reference", &[host, session, own, json]),
            StatusCode::FORBIDDEN
        );
        assert_eq!(
            run(
                &Method::POST,
                "/reference",
                &[
                    host,
                    session,
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
                &[host, session, own, json, with_csrf]
            ),
            StatusCode::OK
        );
        // A form post (no JSON) is still refused even with the CSRF value.
        assert_eq!(
            run(
                &Method::POST,
                "/reference",
                &[host, session, own, with_csrf]
            ),
            StatusCode::UNSUPPORTED_MEDIA_TYPE
        );
        // A session cannot mint login tickets; the token can.
        assert_eq!(
            run(
                &Method::POST,
                TICKET_PATH,
                &[host, session, own, json, with_csrf]
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

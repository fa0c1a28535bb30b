//! The operator commands' side of the HTTP API: a small blocking client (`ureq`) that the
//! `brdfd reference`, `scan`, `scans`, `show`, `refit`, `abort`, `status`, `export` and
//! `import` commands use, and a reader of the server-sent event stream for live progress.
//!
//! Every request carries the API token (`Authorization: Bearer …`) when the client has one;
//! a 401 answer becomes [`ClientError::Unauthorized`], which says where the token is read from.
//!
//! Every route has a typed call (`status()`, `scan(id)`, `refit(…)`, …) that reads the answer
//! into its type of [`crate::wire`], the contract the daemon's handlers answer with: a field
//! the daemon no longer sends, or sends renamed, is an error naming it
//! ([`ClientError::Contract`]), not a default on the terminal. A newer daemon's extra fields
//! are ignored, and its new states or kinds read as `Unknown` (see [`crate::wire::Open`]).
//! The untyped calls (`get`, `post`, `get_text`, …) give the answer as it came, for tests and
//! tools that look at the bytes themselves.

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::time::Duration;

use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::store::{FitRunId, ScanId};
use crate::wire;

/// The address `brdfd serve` listens on by default (`[api] listen`).
pub const DEFAULT_ADDR: &str = "127.0.0.1:7878";

/// Why a request to the daemon failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Nothing listens on the address. `hint` (empty, or starting with "; ") says where the
    /// address came from and how to point at a daemon elsewhere.
    #[error("no brdfd daemon is listening on {addr} — start one with `brdfd serve`{hint}")]
    NotRunning { addr: SocketAddr, hint: String },
    /// The daemon wants the API token, or another one.
    #[error("the daemon on {addr} refused the request: {message} (this command {token_source})")]
    Unauthorized {
        addr: SocketAddr,
        message: String,
        token_source: String,
    },
    /// The daemon refused the request; its message says why and what to do, and `kind` (the
    /// API's machine-readable word, empty when it gave none) what sort of refusal it is.
    #[error("{message}")]
    Refused {
        status: u16,
        kind: String,
        message: String,
    },
    /// The daemon's answer is not the type this client reads for the route (a field missing
    /// or renamed): daemon and client are of versions that do not agree.
    #[error(
        "the daemon on {addr} answered {route} with JSON this brdfd cannot read ({detail}); is \
         the daemon a different version? (`brdfd status --json`, `brdfd --version`)"
    )]
    Contract {
        addr: SocketAddr,
        route: String,
        detail: String,
    },
    /// The connection failed in another way.
    #[error("talking to the brdfd daemon on {addr}: {detail}")]
    Transport { addr: SocketAddr, detail: String },
}

impl ClientError {
    /// Whether the daemon answered 409 Conflict (busy, or a state that forbids the request).
    pub fn is_conflict(&self) -> bool {
        matches!(self, ClientError::Refused { status: 409, .. })
    }

    /// Whether asking again later may succeed: the instruments are busy, the daemon is shutting
    /// down, or it is at a connection or subscriber limit (503).
    pub fn is_busy(&self) -> bool {
        match self {
            ClientError::Refused { status, kind, .. } => {
                *status == 503 || kind == "busy" || kind == "shutting_down"
            }
            _ => false,
        }
    }
}

/// The message and kind of a refusal's JSON body (or the body itself, when it is not one).
fn refusal(status: u16, body: &str) -> ClientError {
    let parsed: Option<wire::ErrorBody> = serde_json::from_str(body).ok();
    match parsed {
        Some(b) => ClientError::Refused {
            status,
            kind: b.kind.unwrap_or_default(),
            message: b.error,
        },
        None => ClientError::Refused {
            status,
            kind: String::new(),
            message: format!("HTTP {status}: {body}"),
        },
    }
}

/// A client of one daemon.
#[derive(Debug, Clone)]
pub struct Client {
    addr: SocketAddr,
    /// `Bearer …`, when a token is known.
    authorization: Option<String>,
    /// Where the token came from (or why there is none), for the 401 message.
    token_source: String,
    /// Added to the "no daemon" message ([`ClientError::NotRunning`]).
    not_running_hint: String,
    agent: ureq::Agent,
    /// For the event stream: no overall timeout (it lasts as long as the scan).
    stream_agent: ureq::Agent,
}

impl Client {
    pub fn new(addr: SocketAddr) -> Client {
        let agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_connect(Some(Duration::from_secs(2)))
            .timeout_global(Some(Duration::from_secs(60)))
            .build()
            .into();
        let stream_agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_connect(Some(Duration::from_secs(2)))
            .build()
            .into();
        Client {
            addr,
            authorization: None,
            token_source: "sent no token".into(),
            not_running_hint: String::new(),
            agent,
            stream_agent,
        }
    }

    /// Sends `token` with every request; `source` says where it came from (for messages),
    /// e.g. "read the token from /var/lib/brdfd/brdfd.token".
    pub fn with_token(mut self, token: &crate::api::Token, source: impl Into<String>) -> Client {
        self.authorization = Some(format!("Bearer {}", token.as_str()));
        self.token_source = source.into();
        self
    }

    /// Adds `hint` ("; …": where the address came from, how to name another) to the message
    /// when no daemon listens on the address.
    pub fn with_not_running_hint(mut self, hint: impl Into<String>) -> Client {
        self.not_running_hint = hint.into();
        self
    }

    /// Says why no token is sent (e.g. the token file could not be read), for the 401 message.
    pub fn without_token(mut self, why: impl Into<String>) -> Client {
        self.authorization = None;
        self.token_source = why.into();
        self
    }

    fn get_request(&self, path: &str) -> ureq::RequestBuilder<ureq::typestate::WithoutBody> {
        let r = self.agent.get(&self.url(path));
        match &self.authorization {
            Some(a) => r.header("authorization", a),
            None => r,
        }
    }

    fn post_request(&self, path: &str) -> ureq::RequestBuilder<ureq::typestate::WithBody> {
        let r = self
            .agent
            .post(&self.url(path))
            .header("content-type", "application/json");
        match &self.authorization {
            Some(a) => r.header("authorization", a),
            None => r,
        }
    }

    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    fn transport(&self, e: ureq::Error) -> ClientError {
        let refused = match &e {
            ureq::Error::ConnectionFailed => true,
            ureq::Error::Io(io) => matches!(
                io.kind(),
                std::io::ErrorKind::ConnectionRefused | std::io::ErrorKind::ConnectionReset
            ),
            _ => false,
        };
        if refused {
            ClientError::NotRunning {
                addr: self.addr,
                hint: self.not_running_hint.clone(),
            }
        } else {
            ClientError::Transport {
                addr: self.addr,
                detail: e.to_string(),
            }
        }
    }

    fn finish(
        &self,
        response: Result<ureq::http::Response<ureq::Body>, ureq::Error>,
    ) -> Result<String, ClientError> {
        let mut response = response.map_err(|e| self.transport(e))?;
        let status = response.status().as_u16();
        let body = response
            .body_mut()
            .read_to_string()
            .map_err(|e| self.transport(e))?;
        if (200..300).contains(&status) {
            Ok(body)
        } else {
            let refused = refusal(status, &body);
            if status == 401 {
                let ClientError::Refused { message, .. } = refused else {
                    unreachable!("refusal() makes a Refused")
                };
                return Err(ClientError::Unauthorized {
                    addr: self.addr,
                    message,
                    token_source: self.token_source.clone(),
                });
            }
            Err(refused)
        }
    }

    fn json(&self, text: String) -> Result<Value, ClientError> {
        serde_json::from_str(&text).map_err(|e| ClientError::Transport {
            addr: self.addr,
            detail: format!("the daemon's answer is not JSON: {e}"),
        })
    }

    /// `GET path` → JSON.
    pub fn get(&self, path: &str) -> Result<Value, ClientError> {
        let text = self.finish(self.get_request(path).call())?;
        self.json(text)
    }

    /// `GET path` → text.
    pub fn get_text(&self, path: &str) -> Result<String, ClientError> {
        self.finish(self.get_request(path).call())
    }

    /// `GET path` → bytes (a PNG preview); a refusal is read as the JSON error it is.
    pub fn get_bytes(&self, path: &str) -> Result<Vec<u8>, ClientError> {
        let mut response = self
            .get_request(path)
            .call()
            .map_err(|e| self.transport(e))?;
        let status = response.status().as_u16();
        let body = response
            .body_mut()
            .with_config()
            .limit(64 << 20)
            .read_to_vec()
            .map_err(|e| self.transport(e))?;
        if (200..300).contains(&status) {
            return Ok(body);
        }
        Err(refusal(status, &String::from_utf8_lossy(&body)))
    }

    /// `POST path` with a JSON body (or none) → JSON.
    pub fn post(&self, path: &str, body: Option<&Value>) -> Result<Value, ClientError> {
        let text = self.post_for_text(path, body.map(Value::to_string).as_deref())?;
        self.json(text)
    }

    /// `POST path` with a JSON body as text (or none) → the answer's text, as it came.
    pub fn post_for_text(&self, path: &str, body: Option<&str>) -> Result<String, ClientError> {
        let request = self.post_request(path);
        let response = match body {
            Some(b) => request.send(b),
            None => request.send_empty(),
        };
        self.finish(response)
    }

    /// `POST path` with a text body (a scan file) → JSON.
    pub fn post_text(&self, path: &str, body: &str) -> Result<Value, ClientError> {
        let response = self.post_request(path).send(body);
        let text = self.finish(response)?;
        self.json(text)
    }

    /// `POST path` with a binary body (an instrument export such as an X-Rite `.xlsx`) → JSON.
    pub fn post_bytes(&self, path: &str, body: &[u8]) -> Result<Value, ClientError> {
        let text = self.post_bytes_for_text(path, body)?;
        self.json(text)
    }

    /// `POST path` with a binary body → the answer's text, as it came.
    pub fn post_bytes_for_text(&self, path: &str, body: &[u8]) -> Result<String, ClientError> {
        let r = self
            .agent
            .post(&self.url(path))
            .header("content-type", crate::api::access::XLSX_MEDIA_TYPE);
        let r = match &self.authorization {
            Some(a) => r.header("authorization", a),
            None => r,
        };
        let response = r.send(body);
        self.finish(response)
    }

    /// The answer `text` to `route` read as its wire type.
    fn typed<T: DeserializeOwned>(&self, route: &str, text: &str) -> Result<T, ClientError> {
        serde_json::from_str(text).map_err(|e| ClientError::Contract {
            addr: self.addr,
            route: route.to_string(),
            detail: e.to_string(),
        })
    }

    fn get_typed<T: DeserializeOwned>(&self, path: &str) -> Result<T, ClientError> {
        let text = self.get_text(path)?;
        self.typed(&format!("GET {path}"), &text)
    }

    fn post_typed<T: DeserializeOwned, B: serde::Serialize>(
        &self,
        path: &str,
        body: Option<&B>,
    ) -> Result<T, ClientError> {
        let body = body
            .map(|b| serde_json::to_string(b))
            .transpose()
            .map_err(|e| ClientError::Transport {
                addr: self.addr,
                detail: format!("the request could not be written as JSON: {e}"),
            })?;
        let text = self.post_for_text(path, body.as_deref())?;
        self.typed(&format!("POST {path}"), &text)
    }

    /// `GET /healthz`.
    pub fn health(&self) -> Result<wire::Health, ClientError> {
        self.get_typed("/healthz")
    }

    /// `GET /status`.
    pub fn status(&self) -> Result<wire::Status, ClientError> {
        self.get_typed("/status")
    }

    /// `POST /reference`: measure the white reference tile.
    pub fn request_reference(&self) -> Result<wire::ReferenceAccepted, ClientError> {
        self.post_typed::<_, ()>("/reference", None)
    }

    /// `POST /scans`: scan `sample`.
    pub fn request_scan(&self, sample: &str) -> Result<wire::ScanAccepted, ClientError> {
        let body = wire::ScanRequest {
            sample: sample.to_string(),
        };
        self.post_typed("/scans", Some(&body))
    }

    /// `GET /scans` with the query's parameters, newest first.
    pub fn scans(&self, query: &wire::ScanQuery) -> Result<Vec<wire::ScanSummary>, ClientError> {
        self.get_typed(&scans_path(query))
    }

    /// `GET /scans/{id}`.
    pub fn scan(&self, scan: ScanId) -> Result<wire::ScanView, ClientError> {
        self.get_typed(&format!("/scans/{scan}"))
    }

    /// `GET /scans/{id}/export`: the scan as a `brdfd.scan/1` file, its text as sent.
    pub fn export_scan(&self, scan: ScanId) -> Result<String, ClientError> {
        self.get_text(&format!("/scans/{scan}/export"))
    }

    /// `POST /scans/import` of a `brdfd.scan/1` file's text, with the file's name and whether
    /// to import it again if it was imported before.
    pub fn import_scan(
        &self,
        file: &str,
        query: &wire::ImportQuery,
    ) -> Result<wire::Imported, ClientError> {
        let text = self.finish(self.post_request(&import_path(query)).send(file))?;
        self.typed("POST /scans/import", &text)
    }

    /// `POST /scans/import` of an X-Rite QC `.xlsx` export, as [`Client::import_scan`].
    pub fn import_xlsx(
        &self,
        bytes: &[u8],
        query: &wire::ImportQuery,
    ) -> Result<wire::Imported, ClientError> {
        let text = self.post_bytes_for_text(&import_path(query), bytes)?;
        self.typed("POST /scans/import", &text)
    }

    /// `POST /scans/{id}/refit`.
    pub fn refit(
        &self,
        scan: ScanId,
        request: &wire::RefitRequest,
    ) -> Result<wire::RefitAccepted, ClientError> {
        self.post_typed(&format!("/scans/{scan}/refit"), Some(request))
    }

    /// `POST /abort`: stop the reference or scan in progress.
    pub fn abort(&self) -> Result<wire::Aborted, ClientError> {
        self.post_typed::<_, ()>("/abort", None)
    }

    /// `GET /fits/{id}`.
    pub fn fit(&self, fit: FitRunId) -> Result<wire::FitDetail, ClientError> {
        self.get_typed(&format!("/fits/{fit}"))
    }

    /// `POST /fits/{id}/cancel`.
    pub fn cancel_fit(&self, fit: FitRunId) -> Result<wire::Cancelling, ClientError> {
        self.post_typed::<_, ()>(&format!("/fits/{fit}/cancel"), None)
    }

    /// `GET /fits/{id}/preview.png`.
    pub fn fit_preview(&self, fit: FitRunId) -> Result<Vec<u8>, ClientError> {
        self.get_bytes(&format!("/fits/{fit}/preview.png"))
    }

    /// `GET /scans/{id}/textures/{position}.png`.
    pub fn scan_texture(&self, scan: ScanId, position: u32) -> Result<Vec<u8>, ClientError> {
        self.get_bytes(&format!("/scans/{scan}/textures/{position}.png"))
    }

    /// `GET /scans/{id}/swatches`.
    pub fn swatches(&self, scan: ScanId) -> Result<wire::Swatches, ClientError> {
        self.get_typed(&format!("/scans/{scan}/swatches"))
    }

    /// `GET /scans/{id}/readings`.
    pub fn scan_readings(&self, scan: ScanId) -> Result<Vec<wire::BenchReading>, ClientError> {
        self.get_typed(&format!("/scans/{scan}/readings"))
    }

    /// `GET /bench`.
    pub fn bench(&self) -> Result<wire::Bench, ClientError> {
        self.get_typed("/bench")
    }

    /// `POST /session/ticket`: a one-time login link for the web page.
    pub fn ticket(&self) -> Result<wire::Ticket, ClientError> {
        self.post_typed::<_, ()>(crate::api::access::TICKET_PATH, None)
    }

    /// `GET /session`.
    pub fn session(&self) -> Result<wire::Session, ClientError> {
        self.get_typed("/session")
    }

    /// Opens the event stream. Subscribe before making a request whose progress you want,
    /// so no event is missed.
    pub fn events(&self) -> Result<EventStream, ClientError> {
        let mut request = self.stream_agent.get(&self.url("/events"));
        if let Some(a) = &self.authorization {
            request = request.header("authorization", a);
        }
        let response = request.call().map_err(|e| self.transport(e))?;
        if !response.status().is_success() {
            let status = response.status().as_u16();
            // The refusal's own message, through the same path as every other request.
            return Err(self
                .finish(Ok(response))
                .err()
                .unwrap_or(ClientError::Refused {
                    status,
                    kind: String::new(),
                    message: "the daemon refused the event stream".into(),
                }));
        }
        Ok(EventStream {
            lines: Box::new(BufReader::new(response.into_body().into_reader())),
        })
    }
}

/// The path of `GET /scans` with the query's parameters, percent-encoded.
pub fn scans_path(query: &wire::ScanQuery) -> String {
    let mut params = Vec::new();
    if let Some(limit) = query.limit {
        params.push(format!("limit={limit}"));
    }
    if let Some(before) = query.before {
        params.push(format!("before={before}"));
    }
    for (key, value) in [
        ("state", &query.state),
        ("sample", &query.sample),
        ("sample_contains", &query.sample_contains),
    ] {
        if let Some(v) = value {
            params.push(format!("{key}={}", urlencode(v)));
        }
    }
    if params.is_empty() {
        "/scans".into()
    } else {
        format!("/scans?{}", params.join("&"))
    }
}

/// A percent-encoding of a query value (sample names have spaces and dots).
/// `/scans/import` with the query's parameters.
fn import_path(q: &wire::ImportQuery) -> String {
    let mut params = Vec::new();
    if let Some(f) = &q.file {
        params.push(format!("file={}", urlencode(f)));
    }
    if q.again {
        params.push("again=true".to_string());
    }
    if params.is_empty() {
        "/scans/import".to_string()
    } else {
        format!("/scans/import?{}", params.join("&"))
    }
}

fn urlencode(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// The server-sent events of `GET /events`, one JSON object per event.
pub struct EventStream {
    lines: Box<dyn BufRead + Send>,
}

impl std::fmt::Debug for EventStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("EventStream")
    }
}

impl Iterator for EventStream {
    type Item = Value;

    /// The next event's JSON (with its `"type"`); `None` when the daemon closed the stream.
    fn next(&mut self) -> Option<Value> {
        let mut data = String::new();
        loop {
            let mut line = String::new();
            match self.lines.read_line(&mut line) {
                Ok(0) | Err(_) => return None,
                Ok(_) => {}
            }
            let line = line.trim_end_matches(['\r', '\n']);
            if line.is_empty() {
                // End of one event; keep-alive comments have no data.
                if !data.is_empty() {
                    if let Ok(v) = serde_json::from_str(&data) {
                        return Some(v);
                    }
                    data.clear();
                }
            } else if let Some(d) = line.strip_prefix("data:") {
                data.push_str(d.strip_prefix(' ').unwrap_or(d));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_values_are_percent_encoded() {
        assert_eq!(urlencode("T.Sky blue"), "T.Sky%20blue");
        assert_eq!(urlencode("a&b=c"), "a%26b%3Dc");
    }

    #[test]
    fn the_scans_path_carries_each_parameter_given() {
        let q = wire::ScanQuery {
            limit: Some(20),
            before: Some(7),
            state: Some("complete".into()),
            sample: Some("T.Sky blue".into()),
            sample_contains: None,
        };
        assert_eq!(
            scans_path(&q),
            "/scans?limit=20&before=7&state=complete&sample=T.Sky%20blue"
        );
        assert_eq!(scans_path(&wire::ScanQuery::default()), "/scans");
    }
}

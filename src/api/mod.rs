//! The local HTTP API (axum, HTTP/1.1, JSON), on loopback by default (`[api] listen`).
//!
//! Every JSON body below is a type of [`crate::wire`], the contract the client reads back.
//!
//! | method and path | does | answers |
//! |---|---|---|
//! | `GET /healthz` | liveness, for monitoring; needs no token | 200 [`wire::Health`] `{"ok": true}` |
//! | `GET /status` | the daemon's state | 200 [`wire::Status`] |
//! | `POST /reference` | measure the white reference tile | 202 `{"reference": id}` |
//! | `POST /scans` `{"sample": "…"}` | scan a sample | 202 `{"scan": id}` |
//! | `GET /scans?state=&sample=&sample_contains=&limit=&before=` | list scans, newest first (`sample`: that name; `sample_contains`: names holding that text, any case; `limit` ≤ 500; `before=ID` pages on) | 200 `[summary]` |
//! | `GET /scans/{id}` | a scan, its readings, reference and fits | 200 |
//! | `GET /scans/{id}/export` | the scan as `brdfd.scan/1` | 200 |
//! | `GET /scans/{id}/textures/{n}.png` | the instrument camera's image `n` kept with an imported scan (listed in the scan's `textures`) | 200 `image/png` |
//! | `POST /scans/import?file=NAME&again=true` (a `brdfd.scan/1` body, or an X-Rite QC `.xlsx` export; both parameters optional) | import its scans, fit them; the same bytes imported before (through any door) are not imported again unless `again=true` | 201 `{"scan", "fits"}` (an `.xlsx`: `"scans"` and `"colorimetry_checks"` too); 200 `{"scan", "scans", "fits": [], "already_imported": {"message", …}}` for a repeat |
//! | `POST /scans/{id}/refit` [`RefitRequest`] (`preset`, `model`, `fresnel`, `sra`, `sra_weight`, `missing_only`) | queue fits again | 202 `{"fits": [id]}` |
//! | `POST /abort` | stop the reference or scan in progress | 200 `{"aborted": …}` |
//! | `GET /fits/{id}` | a fit run and its evaluation | 200 |
//! | `POST /fits/{id}/cancel` | cancel a queued or running fit | 202 |
//! | `GET /fits/{id}/preview.png` | the fitted material on a sphere ([`crate::render`]) | 200 `image/png` |
//! | `GET /events` | server-sent events, one per [`crate::service::Event`] | `text/event-stream` |
//! | `GET /`, `/login`, `/session`, … | the operator's web page and its session ([`web`]) | |
//!
//! Every request but `GET /healthz` and the page's own files needs `Authorization: Bearer
//! <token>` (or the web page's session cookie, see [`access`]); Host, Origin and
//! body type are checked before any route runs ([`access`]); connections, header reads, idle
//! connections, bodies (1 MiB) and event streams are bounded ([`server`], [`MAX_BODY_BYTES`]);
//! the bodies of `POST /scans/import` held at once are bounded as a whole by the service's
//! import budget (`[ingest] max_held_mib`), held before a byte is read (503 when full).
//!
//! Every refusal is a JSON object `{"error": "…"}` whose message says what to do; the status
//! code says which kind: 404 no such thing, 409 the instruments are busy or the state forbids
//! it, 422 an invalid scan file, 400 a bad argument, 503 shutting down or at a limit; the
//! guard adds 401 (no or wrong token), 403 (foreign origin), 413 (body over 1 MiB), 415 (body
//! not JSON) and 421 (a host name the daemon does not answer to).

pub mod access;
mod answer;
pub mod metrics;
pub mod server;
pub mod web;

use std::convert::Infallible;
use std::net::SocketAddr;
use std::time::Duration;

use std::sync::Arc;

use axum::extract::{DefaultBodyLimit, Extension, Path, Query, State};
use axum::http::StatusCode;
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use tokio::sync::{Semaphore, watch};
use tokio_stream::StreamExt;
use tokio_stream::wrappers::BroadcastStream;

pub use access::{Access, Token, TokenError};
pub use server::ConnectionLimits;

use crate::config::ApiConfig;
use crate::scan::Scan;
use crate::service::{RefitRequest, Service, ServiceError};
use crate::store::{FitRunId, ScanFilter, ScanId, ScanState, StoreError};
use crate::wire;
pub use crate::wire::{ErrorBody, ScanQuery, ScanRequest as ScanRequestBody};

/// An error as the API sends it.
#[derive(Debug)]
pub struct ApiError(pub ServiceError);

impl From<ServiceError> for ApiError {
    fn from(e: ServiceError) -> Self {
        ApiError(e)
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        ApiError(ServiceError::Store(e))
    }
}

impl ApiError {
    /// What kind of refusal this is: `busy` and `shutting_down` mean "retry later";
    /// `no_reference`, `idle`, `not_complete`, `stale_reference`, `conflict` that the request
    /// does not fit the daemon's state; `not_found`; `bad_request`, `invalid_scan`,
    /// `processing` that the request itself is wrong; `store` a failure of the store.
    pub fn kind(&self) -> &'static str {
        match &self.0 {
            ServiceError::Busy { .. } => "busy",
            ServiceError::ShuttingDown => "shutting_down",
            ServiceError::NoReference => "no_reference",
            ServiceError::Idle => "idle",
            ServiceError::NotComplete { .. } => "not_complete",
            ServiceError::StaleReference { .. } => "stale_reference",
            ServiceError::BadRequest(_) => "bad_request",
            ServiceError::InvalidScan(_) => "invalid_scan",
            ServiceError::Processing(_) => "processing",
            ServiceError::Store(StoreError::NotFound { .. }) => "not_found",
            ServiceError::Store(
                StoreError::ScanState { .. }
                | StoreError::FitState { .. }
                | StoreError::ReferenceState { .. }
                | StoreError::AlreadyProcessed { .. },
            ) => "conflict",
            ServiceError::Store(_) => "store",
        }
    }

    pub fn status(&self) -> StatusCode {
        match &self.0 {
            ServiceError::Busy { .. }
            | ServiceError::NoReference
            | ServiceError::Idle
            | ServiceError::NotComplete { .. }
            | ServiceError::StaleReference { .. } => StatusCode::CONFLICT,
            ServiceError::ShuttingDown => StatusCode::SERVICE_UNAVAILABLE,
            ServiceError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ServiceError::InvalidScan(_) | ServiceError::Processing(_) => {
                StatusCode::UNPROCESSABLE_ENTITY
            }
            ServiceError::Store(StoreError::NotFound { .. }) => StatusCode::NOT_FOUND,
            ServiceError::Store(
                StoreError::ScanState { .. }
                | StoreError::FitState { .. }
                | StoreError::ReferenceState { .. }
                | StoreError::AlreadyProcessed { .. },
            ) => StatusCode::CONFLICT,
            ServiceError::Store(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        let error = if status == StatusCode::INTERNAL_SERVER_ERROR {
            tracing::error!(error = %self.0, "request failed");
            INTERNAL_ERROR.to_string()
        } else {
            self.0.to_string()
        };
        (
            status,
            Json(ErrorBody {
                error,
                kind: Some(self.kind().to_string()),
            }),
        )
            .into_response()
    }
}

type ApiResult<T> = Result<T, ApiError>;

/// A request body or query the extractor refused: the answer names the problem and says what
/// to send, without the parser's internals (its list of expected fields, byte positions),
/// which go to the log.
fn rejected_body(what: &str, expected: &str, detail: &str) -> ServiceError {
    tracing::info!(
        request = what,
        detail,
        "request refused: not the expected shape"
    );
    ServiceError::BadRequest(format!(
        "{what}: {}; {expected}",
        without_parser_internals(detail)
    ))
}

/// A serde or extractor message without its list of expected names and its position: "unknown
/// field `x`, expected one of `a`, `b` at line 1 column 5" → "unknown field `x`".
fn without_parser_internals(detail: &str) -> String {
    // The extractor's prefix ("Failed to deserialize the JSON body into the target type: ").
    let text = detail
        .rsplit_once("target type: ")
        .map_or(detail, |(_, t)| t);
    let text = text.split(" at line ").next().unwrap_or(text);
    let unknown = ["unknown field", "unknown variant"]
        .iter()
        .filter_map(|k| text.find(k))
        .min();
    let text = match unknown.and_then(|at| text[at..].find(", expected").map(|i| at + i)) {
        Some(end) => &text[..end],
        None => text,
    };
    let text = text.trim();
    if text.is_empty() {
        "not a valid request".into()
    } else {
        text.to_string()
    }
}

/// The body of a 500: what happened in words for people, never the store's own error text
/// (SQLite codes, file paths), which stays in the log.
const INTERNAL_ERROR: &str = "the daemon could not do this because its store failed; the daemon's log says why \
     (journalctl -u brdfd, or the terminal running brdfd serve)";

/// The most scans one `GET /scans` returns; page on with `before`.
pub const MAX_LIST_LIMIT: u32 = 500;

/// The largest request body accepted (a scan file is about 30 KiB).
pub const MAX_BODY_BYTES: usize = 1024 * 1024;

/// The largest body `POST /scans/import` accepts: an X-Rite `.xlsx` export carries camera
/// images (1–3 MiB each file); the reader's own cap.
pub const MAX_IMPORT_BODY_BYTES: usize = crate::formats::budget::MAX_UPLOAD_BYTES as usize;

/// Everything [`ApiServer`] needs besides the service: who may call, and the bounds.
#[derive(Debug, Clone)]
pub struct ApiOptions {
    pub access: Access,
    pub connections: ConnectionLimits,
    /// `GET /events` streams at once.
    pub max_event_subscribers: usize,
}

impl ApiOptions {
    /// The defaults of `[api]` with this access.
    pub fn new(access: Access) -> ApiOptions {
        ApiOptions::from_config(&crate::config::Config::default().api, access)
    }

    /// `[api]`'s bounds with this access.
    pub fn from_config(api: &ApiConfig, access: Access) -> ApiOptions {
        ApiOptions {
            access: access.with_allowed_hosts(api.allowed_hosts.iter().cloned()),
            connections: ConnectionLimits {
                max_connections: api.max_connections,
                header_timeout: api.header_timeout,
                idle_timeout: api.idle_timeout,
            },
            max_event_subscribers: api.max_event_subscribers,
        }
    }
}

/// Permits for `GET /events` streams (one is held for the life of each stream), and the
/// keep-alive interval: 15 s, or a third of the idle timeout if that is shorter, so that a
/// quiet stream is never taken for an idle connection.
#[derive(Debug, Clone)]
struct EventPermits(Arc<Semaphore>, Duration);

/// The API's routes on a service, with every request behind [`access::guard()`]. This is the
/// only router brdfd serves.
pub fn router(service: Service, options: &ApiOptions) -> Router {
    let access = Arc::new(options.access.clone());
    let held = service.clone();
    Router::new()
        .route("/healthz", get(healthz))
        .route("/status", get(status))
        .route("/metrics", get(metrics))
        .route("/reference", post(reference))
        .route("/scans", post(request_scan).get(list_scans))
        .route(
            "/scans/import",
            post(import_scan)
                .layer(DefaultBodyLimit::max(MAX_IMPORT_BODY_BYTES))
                .layer(axum::middleware::from_fn_with_state(held, hold_import_body)),
        )
        .route("/scans/{id}", get(show_scan))
        .route("/scans/{id}/export", get(export_scan))
        .route("/scans/{id}/refit", post(refit))
        .route("/scans/{id}/textures/{position}", get(scan_texture))
        .route("/abort", post(abort))
        .route("/fits/{id}", get(show_fit))
        .route("/fits/{id}/cancel", post(cancel_fit))
        .route("/fits/{id}/preview.png", get(fit_preview))
        .route("/events", get(events))
        .merge(web::routes())
        .layer(Extension(access.clone()))
        .layer(Extension(EventPermits(
            Arc::new(Semaphore::new(options.max_event_subscribers)),
            Duration::from_secs(15).min(options.connections.idle_timeout / 3),
        )))
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .layer(axum::middleware::from_fn_with_state(access, access::guard))
        .layer(axum::middleware::map_response(web::security_headers))
        .with_state(service)
}

async fn healthz() -> impl IntoResponse {
    Json(wire::Health { ok: true })
}

/// A refusal that is not a [`ServiceError`]: a limit of the API itself.
fn limit_refusal(status: StatusCode, message: String) -> Response {
    (status, Json(ErrorBody::message(message))).into_response()
}

/// `GET /metrics`: Prometheus text format ([`metrics`]).
async fn metrics(State(s): State<Service>) -> ApiResult<Response> {
    let text = metrics::render(&s).await?;
    Ok((
        [(
            axum::http::header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        text,
    )
        .into_response())
}

async fn status(State(s): State<Service>) -> ApiResult<impl IntoResponse> {
    Ok(Json(s.status().await?))
}

async fn reference(State(s): State<Service>) -> ApiResult<impl IntoResponse> {
    let id = s.request_reference().await?;
    Ok((
        StatusCode::ACCEPTED,
        Json(wire::ReferenceAccepted { reference: id }),
    ))
}

async fn request_scan(
    State(s): State<Service>,
    body: Result<Json<ScanRequestBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<impl IntoResponse> {
    let Json(body) = body
        .map_err(|e| rejected_body("POST /scans", "send {\"sample\": \"NAME\"}", &e.body_text()))?;
    let id = s.request_scan(&body.sample).await?;
    Ok((StatusCode::ACCEPTED, Json(wire::ScanAccepted { scan: id })))
}

async fn list_scans(
    State(s): State<Service>,
    query: Result<Query<ScanQuery>, axum::extract::rejection::QueryRejection>,
) -> ApiResult<impl IntoResponse> {
    let Query(q) = query.map_err(|e| {
        rejected_body(
            "GET /scans",
            "the parameters are state, sample, limit (a number) and before (a scan id)",
            &e.body_text(),
        )
    })?;
    let state = q
        .state
        .as_deref()
        .map(str::parse::<ScanState>)
        .transpose()
        .map_err(|e| {
            ServiceError::BadRequest(format!(
                "{e}: expected requested, measuring, complete, failed or aborted"
            ))
        })?;
    let limit = q.limit.unwrap_or(ScanFilter::default().limit);
    if limit == 0 || limit > MAX_LIST_LIMIT {
        return Err(ApiError(ServiceError::BadRequest(format!(
            "limit={limit} is out of range: 1 to {MAX_LIST_LIMIT}; page on with before=ID (the \
             last id of the previous page)"
        ))));
    }
    let mut filter = ScanFilter {
        state,
        sample: q.sample,
        limit,
        before: q.before.map(ScanId),
    };
    let Some(wanted) = q
        .sample_contains
        .map(|t| t.trim().to_lowercase())
        .filter(|t| !t.is_empty())
    else {
        return Ok(Json(s.store().list_scans(&filter).await?));
    };
    // A name search pages through the scans, newest first, until `limit` match.
    filter.limit = MAX_LIST_LIMIT;
    let mut found = Vec::new();
    loop {
        let page = s.store().list_scans(&filter).await?;
        let full = page.len() == MAX_LIST_LIMIT as usize;
        filter.before = page.last().map(|p| p.id);
        found.extend(
            page.into_iter()
                .filter(|p| p.sample.to_lowercase().contains(&wanted)),
        );
        if found.len() >= limit as usize || !full {
            break;
        }
    }
    found.truncate(limit as usize);
    Ok(Json(found))
}

fn parse_id<T: std::str::FromStr>(what: &str, text: &str) -> Result<T, ApiError> {
    text.parse().map_err(|_| {
        ApiError(ServiceError::BadRequest(format!(
            "\"{text}\" is not a {what} id: ids are whole numbers (see `brdfd scans`)"
        )))
    })
}

async fn show_scan(
    State(s): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<impl IntoResponse> {
    let scan: ScanId = parse_id("scan", &id)?;
    let detail = s.store().scan_detail(scan).await?;
    let mut fits = Vec::new();
    for run in s.store().fits_for_scan(scan).await? {
        fits.push(wire::FitDetail::from(s.store().fit_detail(run.id).await?));
    }
    let r = &detail.reference.reference;
    let done = r.completed_at_ms.unwrap_or(r.taken_at_ms);
    let age_ms = (detail.scan.requested_at_ms - done).max(0);
    let reference_stale = age_ms as u128 > s.settings().reference_max_age.as_millis();
    let textures = s.store().scan_textures(scan).await?;
    Ok(Json(wire::ScanView {
        scan: detail.scan,
        readings: detail.readings.iter().map(Into::into).collect(),
        reference: detail.reference.into(),
        fits,
        reference_age_hours: age_ms as f64 / 3.6e6,
        reference_stale,
        textures,
    }))
}

/// `GET /scans/{id}/textures/{position}.png`: one of the instrument camera's images kept with
/// an imported scan (`textures` in `GET /scans/{id}` lists them), as stored.
async fn scan_texture(
    State(s): State<Service>,
    Path((id, position)): Path<(String, String)>,
) -> ApiResult<impl IntoResponse> {
    let scan: ScanId = parse_id("scan", &id)?;
    let position: u32 = position
        .strip_suffix(".png")
        .and_then(|p| p.parse().ok())
        .ok_or_else(|| {
            ServiceError::BadRequest(format!(
                "\"{position}\" is not a texture image: ask for /scans/{scan}/textures/N.png, N \
                 from the scan's \"textures\" list"
            ))
        })?;
    let png = s.store().scan_texture_png(scan, position).await?;
    Ok((
        [
            (axum::http::header::CONTENT_TYPE, "image/png"),
            // The same position of the same scan is always the same image.
            (
                axum::http::header::CACHE_CONTROL,
                "private, max-age=86400, immutable",
            ),
        ],
        png,
    ))
}

async fn export_scan(
    State(s): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<impl IntoResponse> {
    let scan: ScanId = parse_id("scan", &id)?;
    let file = s.export_scan(scan).await?;
    let text = file.to_json_pretty().map_err(ServiceError::InvalidScan)?;
    Ok((
        [(axum::http::header::CONTENT_TYPE, "application/json")],
        text,
    ))
}

/// Holds a `POST /scans/import` body's bytes in the service's import budget before a byte of
/// it is read (after the guard: only an authorised request holds any), until the import is
/// over. A body whose bytes are not free is refused with 503 naming the bound; one of unknown
/// length is held at the largest size taken.
async fn hold_import_body(
    State(s): State<Service>,
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    use crate::service::import_budget::BudgetError;
    let declared = request
        .headers()
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse::<u64>().ok());
    let largest = MAX_IMPORT_BODY_BYTES as u64;
    let held = match s
        .import_budget()
        .try_hold(declared.unwrap_or(largest).min(largest))
    {
        Ok(held) => held,
        Err(e @ BudgetError::Full { .. }) => {
            let mut r = limit_refusal(StatusCode::SERVICE_UNAVAILABLE, e.to_string());
            r.headers_mut().insert(
                axum::http::header::RETRY_AFTER,
                axum::http::HeaderValue::from_static("1"),
            );
            return r;
        }
        Err(e @ BudgetError::TooLarge { .. }) => {
            return limit_refusal(StatusCode::PAYLOAD_TOO_LARGE, e.to_string());
        }
    };
    let response = next.run(request).await;
    drop(held);
    response
}

async fn import_scan(
    State(s): State<Service>,
    query: Result<Query<wire::ImportQuery>, axum::extract::rejection::QueryRejection>,
    body: Result<axum::body::Bytes, axum::extract::rejection::BytesRejection>,
) -> Result<Response, ApiError> {
    let Query(query) = query.map_err(|e| {
        rejected_body(
            "POST /scans/import",
            "the parameters are file (the file's name) and again (true to import a file \
             imported before)",
            &e.body_text(),
        )
    })?;
    let body = match body {
        Ok(b) => b,
        Err(e) if e.status() == StatusCode::PAYLOAD_TOO_LARGE => {
            return Ok(limit_refusal(
                StatusCode::PAYLOAD_TOO_LARGE,
                format!(
                    "the file is larger than {MAX_IMPORT_BODY_BYTES} bytes; a brdfd.scan/1 file is \
                     about 30 KiB, an X-Rite .xlsx export a few MiB"
                ),
            ));
        }
        Err(e) => {
            return Err(ApiError(ServiceError::BadRequest(format!(
                "POST /scans/import: {e}"
            ))));
        }
    };
    // The name as the file had it, without a directory (a client may send a path).
    let file_name = match query.file.as_deref() {
        Some(f) => {
            let name = f.rsplit(['/', '\\']).next().unwrap_or(f).trim();
            crate::service::check_name("file name", name)?;
            (!name.is_empty()).then(|| name.to_string())
        }
        None => None,
    };
    let sha256 = {
        use sha2::Digest;
        hex::encode(sha2::Sha256::digest(&body))
    };
    let import = Upload {
        sha256,
        file_name,
        again: query.again,
    };
    // An .xlsx is a zip archive; a scan file is JSON text.
    if body.starts_with(b"PK\x03\x04") {
        return import_xrite(&s, body, &import).await;
    }
    if body.len() > MAX_BODY_BYTES {
        return Ok(limit_refusal(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!(
                "the scan file is larger than {MAX_BODY_BYTES} bytes; a brdfd.scan/1 file is \
                 about 30 KiB"
            ),
        ));
    }
    let file = Scan::from_json(&body).map_err(ServiceError::InvalidScan)?;
    let (provenance, taken_at_ms) = crate::service::file_provenance(
        &file,
        crate::service::SCAN_FILE,
        import.file_name.as_deref(),
    )
    .map_err(ServiceError::InvalidScan)?;
    let one = crate::service::ScanToImport {
        scan: &file,
        provenance,
        taken_at_ms,
        textures: &[],
    };
    match s.import_file(import.file(), &[one], import.again).await? {
        crate::service::FileImported::Imported(scans) => {
            let (scan, fits) = scans.into_iter().next().ok_or_else(|| {
                ServiceError::BadRequest("the scan file gave no scan".to_string())
            })?;
            Ok((
                StatusCode::CREATED,
                Json(wire::Imported {
                    already_imported: None,
                    colorimetry_checks: None,
                    fits,
                    scan: Some(scan),
                    scans: None,
                }),
            )
                .into_response())
        }
        crate::service::FileImported::Already(prior) => Ok(already_imported(prior)),
    }
}

/// What `POST /scans/import` knows of the file it receives.
struct Upload {
    /// SHA-256 of the body.
    sha256: String,
    /// The `file` parameter, without a directory.
    file_name: Option<String>,
    /// The `again` parameter.
    again: bool,
}

impl Upload {
    fn file(&self) -> crate::store::ImportFile<'_> {
        crate::store::ImportFile {
            sha256: &self.sha256,
            file_name: self.file_name.as_deref(),
        }
    }
}

/// The answer to a file imported before: 200 with the earlier import's scans, no fit queued.
fn already_imported(prior: crate::store::PriorImport) -> Response {
    let message = format!(
        "{}; add again=true to import it anyway",
        crate::service::already_imported(&prior)
    );
    (
        StatusCode::OK,
        Json(wire::Imported {
            already_imported: Some(wire::AlreadyImported {
                message,
                file_name: prior.file_name,
                imported_at_ms: prior.imported_at_ms,
                sha256: prior.sha256,
            }),
            colorimetry_checks: None,
            fits: Vec::new(),
            scan: prior.scans.first().copied(),
            scans: Some(prior.scans),
        }),
    )
        .into_response()
}

/// `POST /scans/import` of an X-Rite QC `.xlsx` export: every measurement is read and checked
/// before any is imported; all are imported in one transaction, each a scan (reference:
/// instrument calibration, no specular readings) fitted like a measured one.
async fn import_xrite(
    s: &Service,
    body: axum::body::Bytes,
    import: &Upload,
) -> Result<Response, ApiError> {
    // The body itself goes to the reader (no copy: its bytes are what the budget holds).
    let budget = s.settings().budget;
    let name = import
        .file_name
        .clone()
        .unwrap_or_else(|| "the uploaded .xlsx".to_string());
    let read =
        tokio::task::spawn_blocking(move || crate::formats::xrite::read(&body, &name, &budget))
            .await
            .map_err(|e| ServiceError::BadRequest(format!("reading the .xlsx failed: {e}")))?;
    let scans = read.map_err(|e| ServiceError::BadRequest(e.to_string()))?;
    let mut to_import = Vec::with_capacity(scans.len());
    for x in &scans {
        let (provenance, taken_at_ms) = crate::service::file_provenance(
            &x.scan,
            crate::service::XRITE_XLSX,
            import.file_name.as_deref(),
        )
        .map_err(ServiceError::InvalidScan)?;
        to_import.push(crate::service::ScanToImport {
            scan: &x.scan,
            provenance,
            taken_at_ms,
            textures: &x.textures,
        });
    }
    if to_import.is_empty() {
        return Ok((
            StatusCode::CREATED,
            Json(wire::Imported {
                already_imported: None,
                colorimetry_checks: Some(Vec::new()),
                fits: Vec::new(),
                scan: None,
                scans: Some(Vec::new()),
            }),
        )
            .into_response());
    }
    let imported = match s
        .import_file(import.file(), &to_import, import.again)
        .await?
    {
        crate::service::FileImported::Imported(imported) => imported,
        crate::service::FileImported::Already(prior) => return Ok(already_imported(prior)),
    };
    let mut ids = Vec::with_capacity(scans.len());
    let mut all_fits = Vec::new();
    let mut checks = Vec::with_capacity(scans.len());
    for (x, (scan, fits)) in scans.iter().zip(imported) {
        if let Some(w) = x.warning() {
            tracing::warn!(scan = %scan, "{w}");
        }
        ids.push(scan);
        all_fits.extend(fits);
        checks.push(wire::ColorimetryCheck {
            at: x.check.largest_at.to_string(),
            largest_delta_e00: x.check.largest,
            sample: x.scan.sample.clone(),
            scan,
            warning: x.warning(),
        });
    }
    Ok((
        StatusCode::CREATED,
        Json(wire::Imported {
            already_imported: None,
            colorimetry_checks: Some(checks),
            fits: all_fits,
            scan: ids.first().copied(),
            scans: Some(ids),
        }),
    )
        .into_response())
}

async fn refit(
    State(s): State<Service>,
    Path(id): Path<String>,
    body: Result<Json<RefitRequest>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<impl IntoResponse> {
    let scan: ScanId = parse_id("scan", &id)?;
    let Json(request) = body.map_err(|e| {
        rejected_body(
            &format!("POST /scans/{scan}/refit"),
            "send {\"cost_functions\": [\"cf1\", …], \"method\", \"seed\", \"sra\"} (each \
                 optional; GUIDE.md: The HTTP API)",
            &e.body_text(),
        )
    })?;
    let fits = s.refit(scan, &request).await?;
    Ok((StatusCode::ACCEPTED, Json(wire::RefitAccepted { fits })))
}

async fn abort(State(s): State<Service>) -> ApiResult<impl IntoResponse> {
    let op = s.abort()?;
    Ok(Json(wire::Aborted { aborted: op.into() }))
}

async fn show_fit(
    State(s): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<impl IntoResponse> {
    let fit: FitRunId = parse_id("fit", &id)?;
    Ok(Json(wire::FitDetail::from(
        s.store().fit_detail(fit).await?,
    )))
}

/// The sphere preview of one fit, drawn on request on a blocking thread (`cargo bench --bench
/// render` measures it). 409 while the fit has no result.
async fn fit_preview(State(s): State<Service>, Path(id): Path<String>) -> Response {
    let refuse = |status: StatusCode, error: String| {
        (status, Json(ErrorBody::message(error))).into_response()
    };
    let fit: FitRunId = match parse_id("fit", &id) {
        Ok(f) => f,
        Err(e) => return e.into_response(),
    };
    let run = match s.store().fit_detail(fit).await {
        Ok(d) => d.run,
        Err(e) => return ApiError::from(e).into_response(),
    };
    let selection = crate::study::load::Selection::Scans(vec![run.scan]);
    let study = match crate::study::load::from_store(s.store(), &selection).await {
        Ok(study) => study,
        Err(crate::study::load::LoadError::Store(e)) => return ApiError::from(e).into_response(),
        Err(e) => return refuse(StatusCode::CONFLICT, e.to_string()),
    };
    let cost = run.cost_function;
    let drawn = tokio::task::spawn_blocking(move || {
        let mut sample = study
            .samples
            .into_iter()
            .next()
            .ok_or("the scan has no study")?;
        // The study holds the latest finished fit per cost function; draw this one.
        let state = crate::study::load::fit_state(run.scan, &run, &sample.measured)
            .map_err(|e| e.to_string())?;
        if !matches!(state, crate::study::FitState::Done(_)) {
            return Err(format!(
                "fit {fit} is {}, not done: it has no material to draw yet",
                run.status
            ));
        }
        sample.fits = vec![crate::study::FitStudy {
            cost,
            method: run.method.clone(),
            state,
        }];
        crate::render::preview(&sample, &[cost])
            .and_then(|p| p.png())
            .map_err(|e| e.to_string())
    })
    .await;
    match drawn {
        Ok(Ok(png)) => ([(axum::http::header::CONTENT_TYPE, "image/png")], png).into_response(),
        Ok(Err(e)) => refuse(StatusCode::CONFLICT, e),
        Err(e) => {
            tracing::error!(error = %e, %fit, "drawing a preview failed");
            refuse(
                StatusCode::INTERNAL_SERVER_ERROR,
                "drawing the preview failed; the daemon's log says why".into(),
            )
        }
    }
}

async fn cancel_fit(
    State(s): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<impl IntoResponse> {
    let fit: FitRunId = parse_id("fit", &id)?;
    s.cancel_fit(fit).await?;
    Ok((
        StatusCode::ACCEPTED,
        Json(wire::Cancelling { cancelling: fit }),
    ))
}

async fn events(
    State(s): State<Service>,
    Extension(permits): Extension<EventPermits>,
    connection: Option<Extension<server::ConnectionHandle>>,
) -> Response {
    let Ok(permit) = permits.0.clone().try_acquire_owned() else {
        return limit_refusal(
            StatusCode::SERVICE_UNAVAILABLE,
            "too many event streams are open ([api] max_event_subscribers); close one (another \
             `brdfd scan` or browser tab) or try again"
                .into(),
        );
    };
    // From here the connection counts under max_event_subscribers, not max_connections.
    if let Some(Extension(c)) = connection {
        c.become_stream();
    }
    let keep_alive = permits.1;
    tracing::debug!(open = permits.0.available_permits(), "event stream opened");
    let stream = BroadcastStream::new(s.subscribe()).map(move |r| {
        // The permit lives as long as the stream: dropped with it when the client goes.
        let _held = &permit;
        Ok::<_, Infallible>(match r {
            Ok(ev) => SseEvent::default().event(ev.kind()).data(ev.to_json()),
            Err(tokio_stream::wrappers::errors::BroadcastStreamRecvError::Lagged(n)) => {
                SseEvent::default()
                    .event("lagged")
                    .data(format!("{{\"type\":\"lagged\",\"missed\":{n}}}"))
            }
        })
    });
    Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(keep_alive))
        .into_response()
}

/// The HTTP server, running.
#[derive(Debug)]
pub struct ApiServer {
    addr: SocketAddr,
    stop: watch::Sender<bool>,
    task: tokio::task::JoinHandle<()>,
}

/// Why the API could not start.
#[derive(Debug, thiserror::Error)]
pub enum ApiStartError {
    /// The address could not be bound. The message says why once (the system's error is not
    /// repeated as a cause) and what to do.
    #[error("cannot listen on {addr}: {}", bind_advice(*.addr, .error))]
    Bind {
        addr: SocketAddr,
        /// Not a `source`: its text is in the message already.
        error: std::io::Error,
    },
}

/// Why binding `addr` failed and the fix, in one sentence.
fn bind_advice(addr: SocketAddr, source: &std::io::Error) -> String {
    let elsewhere = format!(
        "listen on another port with `brdfd serve --listen {}:PORT` or [api] listen in the \
         configuration file",
        match addr.ip() {
            std::net::IpAddr::V6(ip) => format!("[{ip}]"),
            ip => ip.to_string(),
        }
    );
    match source.kind() {
        std::io::ErrorKind::AddrInUse => format!(
            "the address is already in use, by another brdfd (`brdfd status --addr {addr}`) or \
             another program; stop it, or {elsewhere}"
        ),
        std::io::ErrorKind::PermissionDenied => {
            format!("permission denied (ports below 1024 need privileges); {elsewhere}")
        }
        _ => format!("{source}; {elsewhere}"),
    }
}

impl ApiServer {
    /// Binds `addr` (port 0: any free port) and serves the API on it. The caller has checked
    /// the address ([`crate::config::check_listen`]).
    pub async fn start(
        service: Service,
        addr: SocketAddr,
        options: ApiOptions,
    ) -> Result<ApiServer, ApiStartError> {
        server::raise_fd_limit();
        let listener = server::listen(addr).map_err(|error| ApiStartError::Bind { addr, error })?;
        let addr = listener
            .local_addr()
            .map_err(|error| ApiStartError::Bind { addr, error })?;
        let (stop, stopped) = watch::channel(false);
        let app = router(service, &options);
        let task = tokio::spawn(server::serve(listener, app, options.connections, stopped));
        Ok(ApiServer { addr, stop, task })
    }

    /// Where it listens.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops taking connections and waits up to `grace` for requests in flight; event
    /// streams, which never end by themselves, are cut after that.
    pub async fn stop(mut self, grace: Duration) {
        let _ = self.stop.send(true);
        if tokio::time::timeout(grace, &mut self.task).await.is_err() {
            self.task.abort();
            let _ = (&mut self.task).await;
        }
    }
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod bind_tests {
    #[tokio::test]
    async fn a_port_in_use_is_said_once_with_the_fix() {
        let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = taken.local_addr().unwrap();
        let error = super::server::listen(addr).unwrap_err();
        let e = anyhow::Error::new(super::ApiStartError::Bind { addr, error });
        let line = crate::cli::one_line(&e);
        assert_eq!(line.matches("in use").count(), 1, "{line}");
        assert!(
            !line.to_lowercase().contains("address already in use"),
            "{line}"
        );
        assert!(line.contains("--listen 127.0.0.1:PORT"), "{line}");
        assert!(line.contains("[api] listen"), "{line}");
        assert!(
            line.contains(&format!("brdfd status --addr {addr}")),
            "{line}"
        );
    }
}

#[cfg(test)]
mod body_tests {
    #[test]
    fn refusals_keep_the_problem_and_drop_the_parser_internals() {
        let f = super::without_parser_internals;
        assert_eq!(
            f(
                "Failed to deserialize the JSON body into the target type: unknown field `sampel`, \
               expected `sample` at line 1 column 9"
            ),
            "unknown field `sampel`"
        );
        assert_eq!(
            f("sampel: unknown field `sampel`, expected `sample` at line 1 column 9"),
            "sampel: unknown field `sampel`"
        );
        assert_eq!(
            f(
                "Failed to deserialize the JSON body into the target type: cost_functions[0]: \
               unknown cost function \"cf9\": expected cf1, cf2 or m2 at line 1 column 27"
            ),
            "cost_functions[0]: unknown cost function \"cf9\": expected cf1, cf2 or m2"
        );
    }
}

//! The local HTTP API (axum, HTTP/1.1, JSON), on loopback by default (`[api] listen`).
//!
//! | method and path | does | answers |
//! |---|---|---|
//! | `GET /status` | the daemon's state | 200 [`crate::service::Status`] |
//! | `POST /reference` | measure the white reference tile | 202 `{"reference": id}` |
//! | `POST /scans` `{"sample": "…"}` | scan a sample | 202 `{"scan": id}` |
//! | `GET /scans?state=&sample=&limit=` | list scans, newest first | 200 `[summary]` |
//! | `GET /scans/{id}` | a scan, its readings, reference and fits | 200 |
//! | `GET /scans/{id}/export` | the scan as `brdfd.scan/1` | 200 |
//! | `POST /scans/import` (a `brdfd.scan/1` body) | import a scan, fit it | 201 `{"scan", "fits"}` |
//! | `POST /scans/{id}/refit` [`RefitRequest`] | queue fits again | 202 `{"fits": [id]}` |
//! | `POST /abort` | stop the reference or scan in progress | 200 `{"aborted": …}` |
//! | `GET /fits/{id}` | a fit run and its evaluation | 200 |
//! | `POST /fits/{id}/cancel` | cancel a queued or running fit | 202 |
//! | `GET /fits/{id}/preview.png` | the fitted material on a sphere ([`crate::render`]) | 200 `image/png` |
//! | `GET /events` | server-sent events, one per [`crate::service::Event`] | `text/event-stream` |
//!
//! Every refusal is a JSON object `{"error": "…"}` whose message says what to do; the status
//! code says which kind: 404 no such thing, 409 the instruments are busy or the state forbids
//! it, 422 an invalid scan file, 400 a bad argument, 503 shutting down.

use std::convert::Infallible;
use std::net::SocketAddr;
use std::time::Duration;

use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::{Deserialize, Serialize};
use tokio::sync::oneshot;
use tokio_stream::wrappers::BroadcastStream;
use tokio_stream::{Stream, StreamExt};

use crate::scan::Scan;
use crate::service::{RefitRequest, Service, ServiceError};
use crate::store::{FitDetail, FitRunId, ScanDetail, ScanFilter, ScanId, ScanState, StoreError};

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

/// The body of every refusal.
#[derive(Debug, Serialize, Deserialize)]
pub struct ErrorBody {
    pub error: String,
}

impl ApiError {
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
        if status == StatusCode::INTERNAL_SERVER_ERROR {
            tracing::error!(error = %self.0, "request failed");
        }
        (
            status,
            Json(ErrorBody {
                error: self.0.to_string(),
            }),
        )
            .into_response()
    }
}

type ApiResult<T> = Result<T, ApiError>;

/// `POST /scans` body.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanRequestBody {
    pub sample: String,
}

/// `GET /scans` query.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanQuery {
    pub state: Option<String>,
    pub sample: Option<String>,
    pub limit: Option<u32>,
}

/// `GET /scans/{id}`.
#[derive(Debug, Serialize)]
pub struct ScanView {
    #[serde(flatten)]
    pub detail: ScanDetail,
    /// Every fit run of the scan, oldest first, with its evaluation when done.
    pub fits: Vec<FitDetail>,
    /// Hours between the reference's completion and the scan's request.
    pub reference_age_hours: f64,
    /// Whether that is over `[scan] reference_max_age_hours` (the scan is not fitted then).
    pub reference_stale: bool,
}

/// The API's routes on a service.
pub fn router(service: Service) -> Router {
    Router::new()
        .route("/status", get(status))
        .route("/reference", post(reference))
        .route("/scans", post(request_scan).get(list_scans))
        .route("/scans/import", post(import_scan))
        .route("/scans/{id}", get(show_scan))
        .route("/scans/{id}/export", get(export_scan))
        .route("/scans/{id}/refit", post(refit))
        .route("/abort", post(abort))
        .route("/fits/{id}", get(show_fit))
        .route("/fits/{id}/cancel", post(cancel_fit))
        .route("/fits/{id}/preview.png", get(fit_preview))
        .route("/events", get(events))
        .with_state(service)
}

async fn status(State(s): State<Service>) -> ApiResult<impl IntoResponse> {
    Ok(Json(s.status().await?))
}

async fn reference(State(s): State<Service>) -> ApiResult<impl IntoResponse> {
    let id = s.request_reference().await?;
    Ok((
        StatusCode::ACCEPTED,
        Json(serde_json::json!({ "reference": id })),
    ))
}

async fn request_scan(
    State(s): State<Service>,
    body: Result<Json<ScanRequestBody>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<impl IntoResponse> {
    let Json(body) = body.map_err(|e| ServiceError::BadRequest(format!("POST /scans: {e}")))?;
    let id = s.request_scan(&body.sample).await?;
    Ok((
        StatusCode::ACCEPTED,
        Json(serde_json::json!({ "scan": id })),
    ))
}

async fn list_scans(
    State(s): State<Service>,
    query: Result<Query<ScanQuery>, axum::extract::rejection::QueryRejection>,
) -> ApiResult<impl IntoResponse> {
    let Query(q) = query.map_err(|e| ServiceError::BadRequest(format!("GET /scans: {e}")))?;
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
    let filter = ScanFilter {
        state,
        sample: q.sample,
        limit: q.limit.unwrap_or(ScanFilter::default().limit),
    };
    Ok(Json(s.store().list_scans(&filter).await?))
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
        fits.push(s.store().fit_detail(run.id).await?);
    }
    let r = &detail.reference.reference;
    let done = r.completed_at_ms.unwrap_or(r.taken_at_ms);
    let age_ms = (detail.scan.requested_at_ms - done).max(0);
    let reference_stale = age_ms as u128 > s.settings().reference_max_age.as_millis();
    Ok(Json(ScanView {
        detail,
        fits,
        reference_age_hours: age_ms as f64 / 3.6e6,
        reference_stale,
    }))
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

async fn import_scan(State(s): State<Service>, body: String) -> ApiResult<impl IntoResponse> {
    let file = Scan::from_json(body.as_bytes()).map_err(ServiceError::InvalidScan)?;
    let (scan, fits) = s.import_scan(&file).await?;
    Ok((
        StatusCode::CREATED,
        Json(serde_json::json!({ "scan": scan, "fits": fits })),
    ))
}

async fn refit(
    State(s): State<Service>,
    Path(id): Path<String>,
    body: Result<Json<RefitRequest>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<impl IntoResponse> {
    let scan: ScanId = parse_id("scan", &id)?;
    let Json(request) =
        body.map_err(|e| ServiceError::BadRequest(format!("POST /scans/{scan}/refit: {e}")))?;
    let fits = s.refit(scan, &request).await?;
    Ok((
        StatusCode::ACCEPTED,
        Json(serde_json::json!({ "fits": fits })),
    ))
}

async fn abort(State(s): State<Service>) -> ApiResult<impl IntoResponse> {
    let op = s.abort()?;
    Ok(Json(serde_json::json!({ "aborted": op })))
}

async fn show_fit(
    State(s): State<Service>,
    Path(id): Path<String>,
) -> ApiResult<impl IntoResponse> {
    let fit: FitRunId = parse_id("fit", &id)?;
    Ok(Json(s.store().fit_detail(fit).await?))
}

/// The sphere preview of one fit, drawn on request on a blocking thread (`cargo bench --bench
/// render` measures it). 409 while the fit has no result.
async fn fit_preview(State(s): State<Service>, Path(id): Path<String>) -> Response {
    let refuse =
        |status: StatusCode, error: String| (status, Json(ErrorBody { error })).into_response();
    let fit: FitRunId = match parse_id("fit", &id) {
        Ok(f) => f,
        Err(e) => return e.into_response(),
    };
    let run = match s.store().fit_detail(fit).await {
        Ok(d) => d.run,
        Err(e) => return ApiError::from(e).into_response(),
    };
    let selection = crate::report::load::Selection::Scans(vec![run.scan]);
    let study = match crate::report::load::from_store(s.store(), &selection).await {
        Ok(study) => study,
        Err(crate::report::load::LoadError::Store(e)) => return ApiError::from(e).into_response(),
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
        let state = crate::report::load::fit_state(run.scan, &run, &sample.measured)
            .map_err(|e| e.to_string())?;
        if !matches!(state, crate::report::FitState::Done(_)) {
            return Err(format!(
                "fit {fit} is {}, not done: it has no material to draw yet",
                run.status
            ));
        }
        sample.fits = vec![crate::report::FitStudy {
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
        Err(e) => refuse(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("the preview failed: {e}"),
        ),
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
        Json(serde_json::json!({ "cancelling": fit })),
    ))
}

async fn events(State(s): State<Service>) -> Sse<impl Stream<Item = Result<SseEvent, Infallible>>> {
    let stream = BroadcastStream::new(s.subscribe()).map(|r| {
        Ok(match r {
            Ok(ev) => SseEvent::default().event(ev.kind()).data(ev.to_json()),
            Err(tokio_stream::wrappers::errors::BroadcastStreamRecvError::Lagged(n)) => {
                SseEvent::default()
                    .event("lagged")
                    .data(format!("{{\"type\":\"lagged\",\"missed\":{n}}}"))
            }
        })
    });
    Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
}

/// The HTTP server, running.
#[derive(Debug)]
pub struct ApiServer {
    addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<std::io::Result<()>>,
}

/// Why the API could not start.
#[derive(Debug, thiserror::Error)]
pub enum ApiStartError {
    #[error(
        "cannot listen on {addr}: {source}; is another brdfd running? (`brdfd status`), or \
         change [api] listen"
    )]
    Bind {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
}

impl ApiServer {
    /// Binds `addr` (port 0: any free port) and serves the API on it.
    pub async fn start(service: Service, addr: SocketAddr) -> Result<ApiServer, ApiStartError> {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .map_err(|source| ApiStartError::Bind { addr, source })?;
        let addr = listener
            .local_addr()
            .map_err(|source| ApiStartError::Bind { addr, source })?;
        let (stop, stopped) = oneshot::channel::<()>();
        let app = router(service);
        let task = tokio::spawn(async move {
            axum::serve(listener, app)
                .with_graceful_shutdown(async {
                    let _ = stopped.await;
                })
                .await
        });
        Ok(ApiServer {
            addr,
            stop: Some(stop),
            task,
        })
    }

    /// Where it listens.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops taking connections and waits up to `grace` for requests in flight; event
    /// streams, which never end by themselves, are cut after that.
    pub async fn stop(mut self, grace: Duration) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if tokio::time::timeout(grace, &mut self.task).await.is_err() {
            self.task.abort();
        }
    }
}

#[cfg(test)]
mod tests;

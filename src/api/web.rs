//! The operator's web page, served by the API's own server: the page's files (embedded in the
//! binary from `src/api/web/`: plain HTML, one CSS file and one JavaScript module, no build
//! step, no CDN), the login by one-time ticket that `brdfd open` prints, and the downloads the
//! page offers (exports in each exchange format, the study report as one HTML file).
//!
//! | method and path | does | needs |
//! |---|---|---|
//! | `GET /`, `/app.js`, `/app.css` | the page | nothing (it holds no secret) |
//! | `POST /session/ticket` | a one-time login ticket, for `brdfd open` | the token |
//! | `GET /login?ticket=…` | spends the ticket, sets the session cookie, redirects to `/` | the ticket |
//! | `GET /session` | whether signed in; the session's CSRF value and expiry, for the page's script | nothing |
//! | `POST /session/logout` | ends the session | the cookie |
//! | `GET /scans/{id}/export/{format}` | the scan (and its fits) as CGATS, CxF3, CSV or JSON | token or cookie |
//! | `GET /report.html?scans=1,2[&include_simulated=true]` | the study report of those scans, figures inlined; scans from simulated and real instruments together refused unless `include_simulated` | token or cookie |
//! | `GET /scans/{id}/swatches` | measured and fitted colour per geometry ([`wire::Swatches`]) | token or cookie |
//! | `GET /scans/{id}/readings` | the scan's stored readings as the bench shows them (colour of a spectrum, an SRA value), also for a scan that was aborted or failed | token or cookie |
//! | `GET /bench` | what the bench shows: the operation in progress, or the last scan measured, with its readings and fits so far ([`wire::Bench`]) | token or cookie |
//!
//! The page rebuilds its bench from `GET /bench` when it loads and whenever its event stream
//! reconnects, then applies the events that follow: a reload or a second tab mid-scan shows
//! every reading already stored, not only those whose events it saw.
//!
//! Every response of the server carries the page's security headers ([`security_headers`]):
//! a Content-Security-Policy that allows scripts, styles and connections from the daemon
//! itself only (no inline script), no framing, no referrer (the login link never leaks), and
//! `nosniff`. How a session is checked is in [`super::access`].

use std::sync::Arc;

use axum::extract::{Extension, Path, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use base64::Engine as _;
use serde::Deserialize;

use super::access::{self, Access, SESSION_LIFETIME, Sessions, TICKET_LIFETIME};
use super::{ApiError, ErrorBody, parse_id};
use crate::formats::{self, ExportOptions, Format};
use crate::service::{Service, ServiceError};
use crate::store::ScanId;
use crate::study::load::{LoadError, Selection};
use crate::wire::{
    self, Bench, BenchFit, BenchKind, BenchOperation, BenchReading, FittedSwatches, Swatch,
    Swatches,
};

/// The page, its style and its script, as served.
pub const INDEX_HTML: &str = include_str!("web/index.html");
pub const APP_CSS: &str = include_str!("web/app.css");
pub const APP_JS: &str = include_str!("web/app.js");

/// The Content-Security-Policy of every response: the daemon's own script, style, images
/// and connections only; `data:` images for the swatch favicon and inlined report figures.
pub const CONTENT_SECURITY_POLICY: &str = "default-src 'none'; script-src 'self'; \
     style-src 'self'; img-src 'self' data:; connect-src 'self'; base-uri 'none'; \
     form-action 'none'; frame-ancestors 'none'";

/// The most scans one report download covers (a report draws figures per sample).
pub const MAX_REPORT_SCANS: usize = 50;

/// The page's routes, merged into the API's router (behind the same guard).
pub fn routes() -> Router<Service> {
    Router::new()
        .route("/", get(index))
        .route("/app.js", get(app_js))
        .route("/app.css", get(app_css))
        .route("/login", get(login))
        .route(access::TICKET_PATH, post(ticket))
        .route("/session", get(session))
        .route("/session/logout", post(logout))
        .route("/scans/{id}/export/{format}", get(export_format))
        .route("/report.html", get(report_html))
        .route("/scans/{id}/swatches", get(swatches))
        .route("/bench", get(bench))
        .route("/scans/{id}/readings", get(scan_readings))
}

/// Adds the page's security headers to a response.
pub async fn security_headers(mut response: Response) -> Response {
    let h = response.headers_mut();
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CONTENT_SECURITY_POLICY),
    );
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.entry(header::CACHE_CONTROL)
        .or_insert(HeaderValue::from_static("no-store"));
    response
}

fn asset(content_type: &'static str, body: &'static str) -> Response {
    ([(header::CONTENT_TYPE, content_type)], body).into_response()
}

async fn index() -> Response {
    asset("text/html; charset=utf-8", INDEX_HTML)
}

async fn app_js() -> Response {
    asset("text/javascript; charset=utf-8", APP_JS)
}

async fn app_css() -> Response {
    asset("text/css; charset=utf-8", APP_CSS)
}

#[derive(Debug, Deserialize)]
struct LoginQuery {
    ticket: Option<String>,
}

/// A short HTML answer for the login link (people read it in a browser).
fn login_page(status: StatusCode, message: &str) -> Response {
    let body = format!(
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>brdfd</title>\
         </head><body><h1>brdfd</h1><p>{message}</p></body></html>"
    );
    (
        status,
        [(header::CONTENT_TYPE, "text/html; charset=utf-8")],
        body,
    )
        .into_response()
}

/// `GET /login?ticket=…`: spends the ticket and sets the session cookie.
async fn login(
    Extension(access): Extension<Arc<Access>>,
    query: Result<Query<LoginQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    let ticket = query.ok().and_then(|Query(q)| q.ticket).unwrap_or_default();
    let Some(cookie) = access.sessions().redeem(&ticket) else {
        return login_page(
            StatusCode::UNAUTHORIZED,
            "This login link has been used already or has expired (links last two minutes and \
             work once). Run <code>brdfd open</code> on the lab PC for a new one.",
        );
    };
    let set_cookie = format!(
        "{}={cookie}; HttpOnly; SameSite=Strict; Path=/; Max-Age={}",
        access::SESSION_COOKIE,
        SESSION_LIFETIME.as_secs()
    );
    tracing::info!("web page session opened");
    (
        StatusCode::SEE_OTHER,
        [
            (header::LOCATION, "/".to_string()),
            (header::SET_COOKIE, set_cookie),
        ],
    )
        .into_response()
}

/// `POST /session/ticket` (token only): a login link for `brdfd open`.
async fn ticket(Extension(access): Extension<Arc<Access>>) -> Response {
    let ticket = access.sessions().issue_ticket();
    (
        StatusCode::CREATED,
        Json(wire::Ticket {
            expires_in_s: TICKET_LIFETIME.as_secs(),
            path: format!("/login?ticket={ticket}"),
            ticket,
        }),
    )
        .into_response()
}

/// The session cookie of a request the guard let through with it, if it came that way.
fn verified_cookie<'h>(sessions: &Sessions, headers: &'h HeaderMap) -> Option<&'h str> {
    if headers.contains_key(header::AUTHORIZATION) {
        return None;
    }
    access::session_cookie(headers).filter(|c| sessions.verify(c))
}

fn no_session() -> Response {
    (
        StatusCode::BAD_REQUEST,
        Json(ErrorBody::message(
            "this request carries no web session: the page's session comes from the link \
             `brdfd open` prints",
        )),
    )
        .into_response()
}

/// `GET /session` (open): whether the request carries a session of this daemon, from its own
/// page; if so, what the page's script needs to send POSTs.
async fn session(Extension(access): Extension<Arc<Access>>, headers: HeaderMap) -> Response {
    let cookie =
        verified_cookie(access.sessions(), &headers).filter(|_| access::from_own_page(&headers));
    let Some(cookie) = cookie else {
        let message = if access::session_cookie(&headers).is_some() {
            "the page's session has expired or was ended"
        } else {
            "this browser has no session"
        };
        return Json(wire::Session::SignedOut(wire::SignedOut {
            message: message.to_string(),
            signed_in: false,
        }))
        .into_response();
    };
    Json(wire::Session::SignedIn(wire::SignedIn {
        csrf: access.sessions().csrf(cookie),
        csrf_header: access::CSRF_HEADER.to_string(),
        expires_at_ms: Sessions::expires_at_ms(cookie),
        signed_in: true,
    }))
    .into_response()
}

/// `POST /session/logout`: ends the session and clears the cookie.
async fn logout(Extension(access): Extension<Arc<Access>>, headers: HeaderMap) -> Response {
    let Some(cookie) = verified_cookie(access.sessions(), &headers) else {
        return no_session();
    };
    access.sessions().revoke(cookie);
    tracing::info!("web page session ended");
    (
        [(
            header::SET_COOKIE,
            format!(
                "{}=; HttpOnly; SameSite=Strict; Path=/; Max-Age=0",
                access::SESSION_COOKIE
            ),
        )],
        Json(wire::LoggedOut { logged_out: true }),
    )
        .into_response()
}

fn load_refusal(e: LoadError) -> Response {
    match e {
        LoadError::Store(e) => ApiError::from(e).into_response(),
        e => (
            StatusCode::CONFLICT,
            Json(ErrorBody::message(e.to_string())),
        )
            .into_response(),
    }
}

fn attachment(content_type: &str, name: &str, body: Vec<u8>) -> Response {
    let mut r = body.into_response();
    let h = r.headers_mut();
    if let Ok(v) = HeaderValue::from_str(content_type) {
        h.insert(header::CONTENT_TYPE, v);
    }
    // The name is made of a scan id and fixed words: nothing to escape.
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{name}\"")) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    r
}

/// `GET /scans/{id}/export/{format}`: one scan and its finished fits in an exchange format.
async fn export_format(
    State(s): State<Service>,
    Path((id, format)): Path<(String, String)>,
) -> Response {
    let scan: ScanId = match parse_id("scan", &id) {
        Ok(s) => s,
        Err(e) => return e.into_response(),
    };
    let format: Format = match format.parse() {
        Ok(f) => f,
        Err(e) => return ApiError(ServiceError::BadRequest(e)).into_response(),
    };
    let study = match crate::study::load::from_store(s.store(), &Selection::Scans(vec![scan])).await
    {
        Ok(study) => study,
        Err(e) => return load_refusal(e),
    };
    match formats::export(&study, format, &ExportOptions::default()) {
        Ok(text) => {
            let content_type = match format {
                Format::Cxf3 => "application/xml",
                Format::Json => "application/json",
                Format::Csv => "text/csv; charset=utf-8",
                Format::Cgats => "text/plain; charset=utf-8",
            };
            let name = format!("scan-{scan}.{}", format.extension());
            attachment(content_type, &name, text.into_bytes())
        }
        Err(e) => (
            StatusCode::CONFLICT,
            Json(ErrorBody::message(e.to_string())),
        )
            .into_response(),
    }
}

impl Swatch {
    /// The colour of a BRDF value (sr⁻¹) seen as a reflectance factor, as the report's swatch
    /// figures draw it.
    pub fn of_brdf(f: &crate::spectral::Spectrum) -> Swatch {
        let r = crate::colour::brdf_to_reflectance(f);
        let c = crate::colour::xyz_to_srgb8(crate::colour::reflectance_to_xyz(&r));
        let lab = crate::colour::reflectance_to_lab(&r);
        let round = |v: f64| (v * 100.0).round() / 100.0;
        Swatch {
            srgb: c.hex(),
            clipped: c.clipped,
            lab: [round(lab.l), round(lab.a), round(lab.b)],
        }
    }
}

async fn swatches(State(s): State<Service>, Path(id): Path<String>) -> Response {
    let scan: ScanId = match parse_id("scan", &id) {
        Ok(s) => s,
        Err(e) => return e.into_response(),
    };
    let study = match crate::study::load::from_store(s.store(), &Selection::Scans(vec![scan])).await
    {
        Ok(study) => study,
        Err(e) => return load_refusal(e),
    };
    let Some(sample) = study.samples.into_iter().next() else {
        return ApiError(ServiceError::BadRequest(format!(
            "scan {scan} has no study"
        )))
        .into_response();
    };
    let set = sample.measured.geometries;
    let only = |xs: Vec<Swatch>| -> Vec<Swatch> {
        xs.into_iter()
            .enumerate()
            .filter(|(g, _)| set.contains(*g))
            .map(|(_, x)| x)
            .collect()
    };
    let fits = crate::cost::CostFunction::ALL
        .into_iter()
        .filter_map(|c| {
            let fit = sample.fit(c)?;
            let done = fit.done()?;
            Some(FittedSwatches {
                cost_function: c.into(),
                method: fit.method.clone(),
                estimated: only(done.estimated.iter().map(Swatch::of_brdf).collect()),
                delta_e00: set.iter().map(|g| done.evaluation.at(g.index)).collect(),
                delta_e00_diffuse: done.evaluation.diffuse.mean,
                delta_e00_specular: done.evaluation.specular.map(|s| s.mean),
                delta_e00_all: done.evaluation.all.mean,
            })
        })
        .collect();
    Json(Swatches {
        scan,
        sample: sample.name.clone(),
        geometries: set.iter().map(|g| g.name.to_string()).collect(),
        reference: sample.scan.reference_label().to_string(),
        specular_readings: set.has_sra(),
        measured: only(sample.measured.values.iter().map(Swatch::of_brdf).collect()),
        fits,
    })
    .into_response()
}

fn bench_readings(readings: &[crate::store::Reading]) -> Vec<BenchReading> {
    readings
        .iter()
        .map(|r| BenchReading {
            geometry: r.geometry.name.to_string(),
            device: r.device().into(),
            shown: crate::service::ReadingShown::of(&r.values, r.at_ms),
        })
        .collect()
}

async fn bench_of_scan(
    s: &Service,
    scan: ScanId,
    in_progress: bool,
) -> Result<BenchOperation, ApiError> {
    let detail = s.store().scan_detail(scan).await?;
    let mut fits = Vec::new();
    for run in s.store().fits_for_scan(scan).await? {
        let evaluation = if run.status == crate::store::FitStatus::Done {
            s.store().fit_detail(run.id).await?.evaluation
        } else {
            None
        };
        fits.push(BenchFit {
            fit: run.id,
            cost_function: run.cost_function.into(),
            status: run.status.into(),
            error: run.error.clone(),
            cost: run.result.as_ref().map(|r| r.cost),
            wall_ms: run.result.as_ref().map(|r| r.wall_ms),
            delta_e00_diffuse_mean: evaluation.as_ref().map(|e| e.diffuse.mean),
            delta_e00_specular_mean: evaluation.as_ref().and_then(|e| e.specular.map(|s| s.mean)),
            delta_e00_mean: evaluation.as_ref().map(|e| e.all.mean),
        });
    }
    Ok(BenchOperation {
        kind: BenchKind::Scan.into(),
        id: scan.0,
        sample: detail.scan.sample.clone(),
        state: super::answer::open(detail.scan.state.as_str()),
        reason: detail.scan.reason.clone(),
        in_progress,
        provenance: detail.scan.provenance.clone().map_source(Into::into),
        readings: bench_readings(&detail.readings),
        fits,
    })
}

async fn bench_state(s: &Service) -> Result<Bench, ApiError> {
    use crate::service::Operation;
    let operation = match s.current_operation() {
        Some(Operation::Scan { scan }) => Some(bench_of_scan(s, scan, true).await?),
        Some(Operation::Reference { reference }) => {
            let detail = s.store().reference_detail(reference).await?;
            Some(BenchOperation {
                kind: BenchKind::Reference.into(),
                id: reference.0,
                sample: detail.reference.name.clone(),
                state: super::answer::open(detail.reference.status.as_str()),
                reason: detail.reference.reason.clone(),
                in_progress: true,
                provenance: detail.reference.provenance.clone().map_source(Into::into),
                readings: bench_readings(&detail.readings),
                fits: Vec::new(),
            })
        }
        None => {
            // The last scan the instruments measured (imports are not bench work).
            let recent = s
                .store()
                .list_scans(&crate::store::ScanFilter {
                    limit: 20,
                    ..Default::default()
                })
                .await?;
            match recent
                .iter()
                .find(|r| r.provenance.source != crate::store::Source::Imported)
            {
                Some(r) => Some(bench_of_scan(s, r.id, false).await?),
                None => None,
            }
        }
    };
    Ok(Bench { operation })
}

async fn scan_readings(State(s): State<Service>, Path(id): Path<String>) -> Response {
    let scan: ScanId = match parse_id("scan", &id) {
        Ok(s) => s,
        Err(e) => return e.into_response(),
    };
    match s.store().scan_detail(scan).await {
        Ok(detail) => Json(bench_readings(&detail.readings)).into_response(),
        Err(e) => ApiError::from(e).into_response(),
    }
}

async fn bench(State(s): State<Service>) -> Response {
    match bench_state(&s).await {
        Ok(b) => Json(b).into_response(),
        Err(e) => e.into_response(),
    }
}

#[derive(Debug, Deserialize)]
struct ReportQuery {
    scans: String,
    /// Study scans from simulated instruments together with real ones (refused by default).
    #[serde(default)]
    include_simulated: bool,
}

/// `GET /report.html?scans=1,2`: the study report of those scans as one HTML file, its
/// figures inlined as `data:` images so that it can be saved and opened anywhere.
async fn report_html(
    State(s): State<Service>,
    query: Result<Query<ReportQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    let bad = |m: String| ApiError(ServiceError::BadRequest(m)).into_response();
    let Ok(Query(q)) = query else {
        return bad("GET /report.html needs scans=ID,ID,… (the scans to report)".into());
    };
    let mut ids = Vec::new();
    for part in q.scans.split(',').filter(|p| !p.trim().is_empty()) {
        match parse_id::<ScanId>("scan", part.trim()) {
            Ok(id) if !ids.contains(&id) => ids.push(id),
            Ok(_) => {}
            Err(e) => return e.into_response(),
        }
    }
    if ids.is_empty() || ids.len() > MAX_REPORT_SCANS {
        return bad(format!(
            "a report covers 1 to {MAX_REPORT_SCANS} scans (asked for {}); for more, run \
             `brdfd report` on the lab PC",
            ids.len()
        ));
    }
    let selection = Selection::Scans(ids);
    let study = match crate::study::load::from_store(s.store(), &selection).await {
        Ok(study) => study,
        Err(e) => return load_refusal(e),
    };
    // Real and simulated scans are not pooled unless asked for, as in `brdfd report`.
    let study = match crate::study::load::pool_real_study(study, &selection, q.include_simulated) {
        Ok(study) => study,
        Err(e) => return bad(format!("{e} (include_simulated=true in the query)")),
    };
    let drawn = tokio::task::spawn_blocking(move || -> Result<String, String> {
        let dir = std::env::temp_dir().join(format!(
            "brdfd-report-{}-{}",
            std::process::id(),
            access::random_hex(8)
        ));
        let result = crate::report::write_report(&study, &dir, &mut |_, _, _| {})
            .map_err(|e| e.to_string())
            .and_then(|files| {
                let html = std::fs::read_to_string(&files.html).map_err(|e| e.to_string())?;
                Ok(inline_images(&html, &dir))
            });
        // The files were only needed to build the one page.
        if let Err(e) = std::fs::remove_dir_all(&dir) {
            tracing::warn!(dir = %dir.display(), error = %e, "cannot remove the report's temporary files");
        }
        result
    })
    .await;
    match drawn {
        Ok(Ok(html)) => {
            let mut r = attachment("text/html; charset=utf-8", "brdfd-report.html", html.into());
            // Opened from the daemon, the report may show its inlined images and nothing else.
            r.headers_mut().insert(
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static(
                    "default-src 'none'; img-src data:; style-src 'unsafe-inline'",
                ),
            );
            r
        }
        Ok(Err(e)) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            Json(ErrorBody::message(format!("the report failed: {e}"))),
        )
            .into_response(),
        Err(e) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            Json(ErrorBody::message(format!("the report failed: {e}"))),
        )
            .into_response(),
    }
}

/// Replaces every `<img src="NAME">` of a report page by the file's content as a `data:` URI
/// (PNG or SVG, read from `dir`); a name with a path separator is left alone.
fn inline_images(html: &str, dir: &std::path::Path) -> String {
    let mut out = String::with_capacity(html.len() * 4);
    let mut rest = html;
    const OPEN: &str = "<img src=\"";
    while let Some(at) = rest.find(OPEN) {
        let start = at + OPEN.len();
        out.push_str(&rest[..start]);
        rest = &rest[start..];
        let Some(end) = rest.find('"') else { break };
        let name = &rest[..end];
        let mime = if name.ends_with(".png") {
            Some("image/png")
        } else if name.ends_with(".svg") {
            Some("image/svg+xml")
        } else {
            None
        };
        match (mime, name.contains(['/', '\\'])) {
            (Some(mime), false) => match std::fs::read(dir.join(name)) {
                Ok(bytes) => {
                    out.push_str("data:");
                    out.push_str(mime);
                    out.push_str(";base64,");
                    out.push_str(&base64::engine::general_purpose::STANDARD.encode(bytes));
                }
                Err(_) => out.push_str(name),
            },
            _ => out.push_str(name),
        }
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_images_are_inlined_and_other_sources_left_alone() {
        let dir = std::env::temp_dir().join(format!("brdfd-inline-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("a.png"), [0x89, b'P', b'N', b'G']).unwrap();
        let html = "<p><img src=\"a.png\" alt=\"x\"><img src=\"../etc/passwd.png\"><img src=\"b.gif\"></p>";
        let out = inline_images(html, &dir);
        assert_eq!(
            out,
            "<p><img src=\"data:image/png;base64,iVBORw==\" alt=\"x\"><img src=\"../etc/passwd.png\"><img src=\"b.gif\"></p>"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_page_lists_the_geometries_in_the_daemons_order() {
        let names: Vec<&str> = crate::geometry::GEOMETRIES.iter().map(|g| g.name).collect();
        let line = format!(
            "const GEOMETRIES = {};",
            serde_json::to_string(&names).unwrap()
        );
        assert!(APP_JS.contains(&line), "app.js must hold {line}");
    }

    #[test]
    fn the_pages_geometry_legend_holds_the_daemons_angles() {
        let rows: Vec<serde_json::Value> = crate::geometry::GEOMETRIES
            .iter()
            .map(|g| {
                serde_json::json!([
                    g.name,
                    g.theta_i_deg as i64,
                    g.theta_r_deg as i64,
                    g.phi_r_deg as i64,
                    g.aspecular_deg as i64
                ])
            })
            .collect();
        let line = format!(
            "const GEOMETRY_ANGLES = {};",
            serde_json::to_string(&rows).unwrap()
        );
        assert!(APP_JS.contains(&line), "app.js must hold {line}");
    }

    #[test]
    fn the_policy_allows_no_inline_script_and_no_other_origin() {
        assert!(CONTENT_SECURITY_POLICY.contains("script-src 'self';"));
        assert!(!CONTENT_SECURITY_POLICY.contains("unsafe-inline"));
        assert!(CONTENT_SECURITY_POLICY.contains("frame-ancestors 'none'"));
        // The page's own files hold no inline script or style and no foreign address.
        assert!(!INDEX_HTML.contains("<script>"));
        assert!(!INDEX_HTML.contains(" style=\""));
        assert!(INDEX_HTML.contains("<script type=\"module\" src=\"/app.js\"></script>"));
        for text in [INDEX_HTML, APP_JS, APP_CSS] {
            assert!(!text.contains("http://") && !text.contains("https://"));
        }
    }
}

//! The HTTP side: the page's files and the API (`/api/info`, `/api/schema`, `/api/run`,
//! `/api/plan`, `/api/capture`, `/api/sim`). Each group of routes has the gate as its
//! layer ([`security::layer`]), so every request is checked before its handler runs; a
//! run is an [`AdmittedRun`], which only the admission makes.

use std::sync::Arc;

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::{DefaultBodyLimit, FromRequest, Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use robobus::catalogue::{self, Request};
use robobus::frontend::{Admitted, PlanView, parse};
use robobus::ops::{OpError, StopToken};

use crate::security::{self, Access};
use crate::{ApiError, App, BODY_TIMEOUT, HEARTBEAT_MS, MAX_BODY, assets, msg};

/// The header that proves control: the secret the controlling page received in its
/// WebSocket's `control` message.
pub(crate) const CONTROL_HEADER: &str = "x-robobus-control";
/// The header earlier studios took as proof of control (a session number anyone could
/// guess): refused on a state-changing request, so that a script using it learns why.
const OLD_SESSION_HEADER: &str = "x-robobus-session";

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = msg::ErrorBody {
            kind: self.kind,
            message: &self.message,
        };
        let mut r = (self.status, axum::Json(body)).into_response();
        if let Some(s) = self.retry_after {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        r
    }
}

impl From<OpError> for ApiError {
    fn from(e: OpError) -> Self {
        Self::of(&e)
    }
}

type ApiResult = Result<Response, ApiError>;

pub(crate) fn router(app: Arc<App>) -> Router {
    // Each group behind its gate: a route added to a group is checked as its group is.
    let gated = |access: Access, routes: Router<Arc<App>>| {
        routes.route_layer(axum::middleware::from_fn_with_state(
            (Arc::clone(&app), access),
            security::layer,
        ))
    };
    let pages = gated(
        Access::Page,
        Router::new()
            .route("/", get(index))
            .route("/static/{*path}", get(file)),
    );
    let reads = gated(
        Access::Read,
        Router::new()
            .route("/api/info", get(info))
            .route("/api/schema", get(schema))
            .route("/api/capture", get(captures))
            .route("/api/capture/{bus}", get(capture))
            .route("/api/sim", get(sim)),
    );
    let changes = gated(
        Access::Change,
        Router::new()
            .route("/api/run", post(run))
            .route("/api/plan", post(plan)),
    );
    let socket = gated(
        Access::Socket,
        Router::new().route("/api/ws", get(crate::ws::upgrade)),
    );
    Router::new()
        .merge(pages)
        .merge(reads)
        .merge(changes)
        .merge(socket)
        .route("/favicon.ico", get(|| async { StatusCode::NO_CONTENT }))
        .fallback(|| async {
            ApiError {
                status: StatusCode::NOT_FOUND,
                kind: "not-found",
                message: "no such page or API path (see /api/info)".into(),
                retry_after: None,
            }
        })
        .layer(DefaultBodyLimit::max(MAX_BODY))
        .with_state(app)
}

fn json(v: &impl serde::Serialize) -> Response {
    axum::Json(v).into_response()
}

fn named(names: &[String]) -> Vec<msg::Named<'_>> {
    names.iter().map(|n| msg::Named { name: n }).collect()
}

async fn info(State(app): State<Arc<App>>) -> Response {
    let (wck, whj) = app.station.names();
    let robot = app.station.robot().map(|r| {
        r.joints
            .iter()
            .map(|j| msg::InfoJoint {
                name: &j.name,
                bus: &j.bus,
                family: r
                    .buses
                    .get(&j.bus)
                    .map_or("whj", |b| if b.is_wck() { "wck" } else { "whj" }),
                id: j.id,
            })
            .collect()
    });
    json(&msg::Info {
        version: env!("CARGO_PKG_VERSION"),
        read_only: app.admission.read_only(),
        simulated: app.sim.is_some(),
        wck: named(&wck),
        whj: named(&whj),
        robot,
        heartbeat_ms: HEARTBEAT_MS,
        heartbeat_timeout_ms: app.guard.config().heartbeat_timeout.as_millis(),
        capture: !app.station.captures().is_empty(),
        eeprom_writes_per_minute: crate::EEPROM_WRITES_PER_MINUTE,
    })
}

async fn schema() -> Response {
    json(&catalogue::schemas())
}

/// The session a state-changing request proves with its control secret: `None` without
/// one (a script: the guard admits its changes only while no page controls, never
/// motion); a secret that is not the controlling page's is refused (403).
fn session(app: &App, headers: &HeaderMap, request: &Request) -> Result<Option<u64>, ApiError> {
    if request.effect() == catalogue::Effect::Read {
        return Ok(None);
    }
    if let Some(secret) = headers.get(CONTROL_HEADER) {
        let secret = secret.to_str().unwrap_or("");
        return app
            .prove(secret)
            .map(Some)
            .map_err(|e| ApiError::forbidden(e.to_string()));
    }
    if headers.contains_key(OLD_SESSION_HEADER) {
        return Err(ApiError::forbidden(format!(
            "{}: X-Robobus-Session is no proof of control: send X-Robobus-Control with the \
             secret of the controlling page's `control` message; nothing was sent",
            request.op()
        )));
    }
    Ok(None)
}

/// A request's body: at most [`MAX_BODY`] bytes (413), sent within [`BODY_TIMEOUT`] (408).
async fn read_body(body: Body) -> Result<Bytes, ApiError> {
    match tokio::time::timeout(BODY_TIMEOUT, axum::body::to_bytes(body, MAX_BODY)).await {
        Ok(Ok(bytes)) => Ok(bytes),
        Ok(Err(e)) => Err(ApiError {
            status: StatusCode::PAYLOAD_TOO_LARGE,
            kind: "bad-input",
            message: format!("the request body: {e} (at most {MAX_BODY} bytes); nothing was sent"),
            retry_after: None,
        }),
        Err(_) => Err(ApiError {
            status: StatusCode::REQUEST_TIMEOUT,
            kind: "bad-input",
            message: format!(
                "the request body did not arrive within {} s; nothing was sent",
                BODY_TIMEOUT.as_secs()
            ),
            retry_after: None,
        }),
    }
}

/// A request to run, admitted: its body read and parsed, its session proved, and the
/// admission passed (read-only, arming and control, the write rate); the only way a
/// handler gets a request it may run.
pub(crate) struct AdmittedRun(Admitted);

impl FromRequest<Arc<App>> for AdmittedRun {
    type Rejection = ApiError;

    async fn from_request(req: axum::extract::Request, app: &Arc<App>) -> Result<Self, ApiError> {
        let (parts, body) = req.into_parts();
        let body = read_body(body).await?;
        let request = parse::request_bytes(&body)?;
        let session = session(app, &parts.headers, &request)?;
        Ok(Self(app.admit(session, request)?))
    }
}

async fn run(State(app): State<Arc<App>>, AdmittedRun(admitted): AdmittedRun) -> ApiResult {
    let report = app.run(admitted, StopToken::new(), None, None).await?;
    Ok(json(&report))
}

async fn plan(body: Body) -> ApiResult {
    let body = read_body(body).await?;
    let request = parse::request_bytes(&body)?;
    Ok(json(&PlanView::of(&request)?))
}

async fn captures(State(app): State<Arc<App>>) -> Response {
    let list: Vec<_> = app
        .station
        .captures()
        .iter()
        .map(|(bus, path)| {
            let bytes = std::fs::symlink_metadata(path)
                .ok()
                .filter(std::fs::Metadata::is_file)
                .map_or(0, |m| m.len());
            let format = if app.station.wck(Some(bus)).is_ok() {
                "hex"
            } else {
                "candump"
            };
            msg::CaptureFile { bus, format, bytes }
        })
        .collect();
    json(&list)
}

async fn capture(State(app): State<Arc<App>>, Path(bus): Path<String>) -> ApiResult {
    let Some((_, path)) = app.station.captures().iter().find(|(b, _)| *b == bus) else {
        return Err(OpError::invalid(
            "bus",
            robobus::ops::cut(&bus),
            format!(
                "no capture of that bus (captured: {})",
                app.station
                    .captures()
                    .iter()
                    .map(|(b, _)| b.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
        .into());
    };
    // Read off the runtime, from the file itself: a symbolic link put in its place is
    // refused, never followed.
    let path = path.clone();
    let data = tokio::task::spawn_blocking(move || {
        let mut file = crate::capture::open_regular(&path)?;
        let mut data = Vec::new();
        std::io::Read::read_to_end(&mut file, &mut data).map(|_| data)
    })
    .await
    .map_err(|e| OpError::Device(format!("reading the capture: {e}")))?
    .map_err(|e| {
        if e.kind() == std::io::ErrorKind::InvalidData {
            OpError::Refused(format!("the capture of {bus}: {e}"))
        } else {
            OpError::Device(format!("reading the capture of {bus}: {e}"))
        }
    })?;
    let mut r = data.into_response();
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; charset=utf-8"),
    );
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{bus}.log\"")) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    Ok(r)
}

async fn sim(State(app): State<Arc<App>>) -> ApiResult {
    match &app.sim {
        Some(sim) => Ok(json(&sim.snapshot())),
        None => Err(ApiError {
            status: StatusCode::NOT_FOUND,
            kind: "not-available",
            message: "this studio drives hardware: the simulators' own state exists only on \
                      the built-in simulated robot"
                .into(),
            retry_after: None,
        }),
    }
}

async fn index() -> ApiResult {
    assets::serve("index.html")
}

async fn file(Path(path): Path<String>) -> ApiResult {
    assets::serve(&format!("static/{path}"))
}

//! `robobus studio`: a local web studio on the request catalogue.
//!
//! A web server (axum, one current-thread runtime) that serves a page embedded in the
//! binary and an HTTP API that is the catalogue itself: `POST /api/run` takes one
//! [`Request`] and answers its [`Report`](robobus::catalogue::Report), `POST /api/plan`
//! its dry run, `GET /api/schema` the JSON Schemas, and one WebSocket (`/api/ws`) carries
//! telemetry, the progress of long operations, jogs and the operator's heartbeat. The
//! server translates and nothing else: every operation, check, jog step and safe stop is
//! the library's ([`robobus::catalogue`], [`Guard`], [`Jogger`]).
//!
//! Safety (the user guide, `docs/studio.md`, says it for users): loopback by default, a
//! token for any other address, `Host` checked on every request and `Origin` on every
//! state-changing one and the WebSocket, no CORS headers, one controlling page, motion
//! only while armed with a heartbeat, a safe stop when it is lost, EEPROM / flash writes
//! rate-limited, and `--read-only`.

// The library's `OpError` is passed through as it is, as every front end does.
#![allow(clippy::result_large_err)]

mod assets;
mod capture;
mod conn;
mod http;
mod msg;
mod security;
mod ws;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use axum::http::StatusCode;
use robobus::ErrorKind;
use robobus::catalogue::Request;
use robobus::frontend::guard::{Guard, GuardConfig, SafeEvent};
use robobus::frontend::live::LiveSimulator;
use robobus::frontend::{Admission, Admitted, Arming, FrontEnd, Refusal, RefusalKind};
use robobus::ops::{OpError, StopToken};
use robobus::station::Station;
use robobus::station::jog::Jogger;

use crate::msg::ToPage;

pub use capture::CaptureDir;
pub use conn::{BODY_TIMEOUT, HEADER_TIMEOUT, MAX_CONNECTIONS};

/// EEPROM, flash and ID writes allowed per minute (the library's admission's).
pub const EEPROM_WRITES_PER_MINUTE: usize = robobus::frontend::admission::WRITES_PER_MINUTE;
/// How often an armed page sends its heartbeat, ms.
pub const HEARTBEAT_MS: u64 = 100;
/// The largest request body, bytes (a motion program or a keyframe file fits easily).
pub const MAX_BODY: usize = 4 << 20;

/// How a studio is served.
#[derive(Debug, Clone)]
pub struct StudioConfig {
    /// Where to listen (`127.0.0.1:PORT` unless the user asks otherwise).
    pub listen: SocketAddr,
    /// The token every API request must carry (required off loopback).
    pub token: Option<String>,
    /// Serve reads only.
    pub read_only: bool,
    /// The operator guard's heartbeat timeout and safe state.
    pub guard: GuardConfig,
}

/// What can go wrong before a studio serves.
#[derive(Debug, thiserror::Error)]
pub enum StudioError {
    /// A non-loopback address without a token.
    #[error(
        "--listen {0}: an address other than loopback needs a token (--token-file FILE): \
         anyone who can reach it could move the robot"
    )]
    NeedsToken(SocketAddr),
    /// The address cannot be bound.
    #[error("--listen {addr}: cannot listen there: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The runtime or the guard's thread could not start.
    #[error("cannot start the studio: {0}")]
    Start(std::io::Error),
}

impl StudioError {
    /// Its kind.
    pub const fn kind(&self) -> ErrorKind {
        match self {
            Self::NeedsToken(_) => ErrorKind::BadInput,
            Self::Bind { .. } | Self::Start(_) => ErrorKind::NotAvailable,
        }
    }
}

/// An error answered to a client: its status, kind and message.
#[derive(Debug)]
pub(crate) struct ApiError {
    pub(crate) status: StatusCode,
    pub(crate) kind: &'static str,
    pub(crate) message: String,
    /// Seconds after which the same request may succeed (`Retry-After`, with 429).
    pub(crate) retry_after: Option<u64>,
}

impl ApiError {
    /// The one mapping of an error kind to an HTTP status.
    pub(crate) fn of(e: &OpError) -> Self {
        let kind = e.kind();
        let status = match kind {
            ErrorKind::BadInput => StatusCode::BAD_REQUEST,
            ErrorKind::Refused => StatusCode::CONFLICT,
            ErrorKind::NoDevice => StatusCode::GATEWAY_TIMEOUT,
            ErrorKind::Interrupted => {
                StatusCode::from_u16(499).unwrap_or(StatusCode::SERVICE_UNAVAILABLE)
            }
            ErrorKind::NotAvailable => StatusCode::NOT_IMPLEMENTED,
            // Device and link failures, and a kind added later until it has its own.
            _ => StatusCode::BAD_GATEWAY,
        };
        Self {
            status,
            kind: kind.name(),
            message: e.to_string(),
            retry_after: None,
        }
    }

    pub(crate) fn forbidden(message: String) -> Self {
        Self {
            status: StatusCode::FORBIDDEN,
            kind: "forbidden",
            message,
            retry_after: None,
        }
    }

    pub(crate) fn unauthorized(message: &str) -> Self {
        Self {
            status: StatusCode::UNAUTHORIZED,
            kind: "unauthorized",
            message: message.to_owned(),
            retry_after: None,
        }
    }
}

impl From<Refusal> for ApiError {
    /// A rate-limited write is 429 with `Retry-After`; the others as their error's kind.
    fn from(r: Refusal) -> Self {
        match r.kind {
            RefusalKind::RateLimited => Self {
                status: StatusCode::TOO_MANY_REQUESTS,
                kind: "rate-limited",
                message: r.error.to_string(),
                retry_after: Some(r.retry_after.map_or(1, |d| d.as_secs().max(1))),
            },
            _ => Self::of(&r.error),
        }
    }
}

/// What every page's connection hears of.
#[derive(Debug, Clone)]
pub(crate) enum Event {
    /// Control or arming changed: each page sends its own view.
    Control,
    /// A JSON message for every page (`safe`, `target`).
    Message(Arc<String>),
    /// The studio is stopping: every page's connection closes.
    Shutdown,
}

/// The server's state.
pub(crate) struct App {
    pub(crate) station: Arc<Station>,
    pub(crate) sim: Option<LiveSimulator>,
    pub(crate) guard: Guard,
    pub(crate) jogger: Jogger,
    pub(crate) gate: security::Gate,
    pub(crate) events: tokio::sync::broadcast::Sender<Event>,
    sessions: AtomicU64,
    /// The control secret of each page (session) that holds control: handed to that page
    /// over its own WebSocket, proof of control on every state-changing request.
    secrets: Mutex<HashMap<u64, security::Secret>>,
    /// Pages connected now (at most `ws::MAX_PAGES`).
    pages: std::sync::atomic::AtomicUsize,
    /// Read-only, arming and the write rate: the library's one admission.
    pub(crate) admission: Admission,
}

impl App {
    pub(crate) fn new_session(&self) -> u64 {
        self.sessions.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// The control secret of `session` while it holds control (made when it first asks
    /// after taking control), `None` otherwise (a secret it had is forgotten).
    pub(crate) fn secret_of(&self, session: u64) -> Option<String> {
        let mut secrets = self.secrets.lock().unwrap_or_else(PoisonError::into_inner);
        if !self.guard.view(session).controller {
            secrets.remove(&session);
            return None;
        }
        if let Some(s) = secrets.get(&session) {
            return Some(s.to_hex());
        }
        let secret = security::Secret::new()?;
        let hex = secret.to_hex();
        secrets.insert(session, secret);
        Some(hex)
    }

    /// Forgets `session`'s secret (its WebSocket closed).
    pub(crate) fn forget_secret(&self, session: u64) {
        self.secrets
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .remove(&session);
    }

    /// The session a control secret proves: the page whose WebSocket is open and holds
    /// control now. Anything else (a guess, a secret of a page that closed or released
    /// control) is refused.
    pub(crate) fn prove(&self, given: &str) -> Result<u64, OpError> {
        let secrets = self.secrets.lock().unwrap_or_else(PoisonError::into_inner);
        // Every entry is compared in full, so the time does not tell which one is near.
        let found = secrets.iter().fold(None, |found, (session, s)| {
            if s.matches(given) {
                Some(*session)
            } else {
                found
            }
        });
        match found {
            Some(session) if self.guard.view(session).controller => Ok(session),
            _ => Err(OpError::Refused(
                "this control secret is not the one of a page that controls this studio now \
                 (it is handed to the controlling page over its own WebSocket, and ends when \
                 that page closes or releases control); nothing was sent"
                    .into(),
            )),
        }
    }

    /// Whether `session` may run `request` now: the admission (read-only, arming and
    /// control through the guard, the write rate).
    pub(crate) fn admit(
        &self,
        session: Option<u64>,
        request: Request,
    ) -> Result<Admitted, ApiError> {
        Ok(self.admission.admit(
            Arming::Guard {
                guard: &self.guard,
                session,
            },
            request,
        )?)
    }

    /// Runs an admitted request on a blocking thread, stopped by `token` or the guard.
    pub(crate) async fn run(
        self: &Arc<Self>,
        admitted: Admitted,
        token: StopToken,
        progress: Option<tokio::sync::mpsc::Sender<String>>,
        id: Option<u64>,
    ) -> Result<robobus::catalogue::Report, OpError> {
        let request = admitted.into_request();
        // Every page's plots show the target from the moment the move starts.
        if let Some((family, bus, device, value)) = target_of(&self.station, &request) {
            self.announce(&ToPage::Target {
                family,
                bus: &bus,
                device,
                value,
                unix_ms: unix_ms(),
            });
        }
        let app = Arc::clone(self);
        tokio::task::spawn_blocking(move || {
            let _ticket = app.guard.running(&token);
            let mut on_progress = |p: &robobus::ops::Progress| {
                if let Some(tx) = &progress {
                    let msg = ToPage::Progress {
                        id,
                        stage: p.stage,
                        done: p.done,
                        total: p.total,
                        note: p.note.as_deref(),
                    };
                    let _ = tx.try_send(msg.text());
                }
            };
            let mut control = robobus::ops::Control::new(&token).with_progress(&mut on_progress);
            robobus::catalogue::run(&app.station, &request, &mut control)
        })
        .await
        .map_err(|e| OpError::Device(format!("the operation's thread failed: {e}")))?
    }

    /// Tells every page about a commanded target.
    pub(crate) fn announce(&self, target: &ToPage<'_>) {
        let _ = self.events.send(Event::Message(Arc::new(target.text())));
    }
}

/// The position target a move commands on its resolved bus (a `target` message for
/// every page's plots): family, bus, device, value. Jogs send theirs as they go; waves,
/// plays and speed or current targets have none of a single value.
fn target_of(
    station: &Station,
    request: &Request,
) -> Option<(robobus::catalogue::Family, String, u32, f64)> {
    use robobus::catalogue::Family;
    Some(match request {
        Request::WhjMove(r) => (
            Family::Whj,
            station.whj(r.bus.as_deref()).ok()?.name().to_owned(),
            r.joint,
            r.degrees,
        ),
        Request::WckMove(r) => (
            Family::Wck,
            station.wck(r.bus.as_deref()).ok()?.name().to_owned(),
            r.id,
            f64::from(r.position),
        ),
        _ => return None,
    })
}

pub(crate) fn unix_ms() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64() * 1e3)
}

/// A studio bound to its address, ready to serve.
pub struct Studio {
    app: Arc<App>,
    listener: std::net::TcpListener,
    addr: SocketAddr,
}

impl std::fmt::Debug for Studio {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Studio")
            .field("addr", &self.addr)
            .finish_non_exhaustive()
    }
}

impl Studio {
    /// Binds `config.listen` for `station` (`sim`: the built-in simulators, for
    /// `GET /api/sim`). Refuses a non-loopback address without a token.
    pub fn bind(
        station: Station,
        sim: Option<LiveSimulator>,
        config: StudioConfig,
    ) -> Result<Self, StudioError> {
        if !config.listen.ip().is_loopback() && config.token.is_none() {
            return Err(StudioError::NeedsToken(config.listen));
        }
        let listener =
            std::net::TcpListener::bind(config.listen).map_err(|source| StudioError::Bind {
                addr: config.listen,
                source,
            })?;
        let addr = listener.local_addr().map_err(StudioError::Start)?;
        let (events, _) = tokio::sync::broadcast::channel(256);
        let station = Arc::new(station);
        let notify = events.clone();
        let guard = Guard::new(Arc::clone(&station), config.guard, move |e: &SafeEvent| {
            let _ = notify.send(Event::Message(Arc::new(ToPage::Safe(e).text())));
            let _ = notify.send(Event::Control);
        })
        .map_err(StudioError::Start)?;
        let gate = security::Gate::new(addr, config.token);
        let admission = Admission::new(
            FrontEnd {
                name: "this studio".into(),
                read_only_how: "started with --read-only".into(),
                arm_how: "take control and arm first".into(),
            },
            config.read_only,
        );
        Ok(Self {
            app: Arc::new(App {
                station,
                sim,
                guard,
                jogger: Jogger::new(),
                gate,
                events,
                sessions: AtomicU64::new(0),
                secrets: Mutex::new(HashMap::new()),
                pages: std::sync::atomic::AtomicUsize::new(0),
                admission,
            }),
            listener,
            addr,
        })
    }

    /// The address it listens on (the port `--port 0` picked).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Serves until `stop` is set; then every moved device is brought to its safe state
    /// (the guard's drop) and the station is closed.
    pub fn serve(self, stop: &StopToken) -> Result<(), StudioError> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(StudioError::Start)?;
        self.listener
            .set_nonblocking(true)
            .map_err(StudioError::Start)?;
        let router = http::router(Arc::clone(&self.app));
        let stop = stop.clone();
        let events = self.app.events.clone();
        rt.block_on(async move {
            let listener =
                tokio::net::TcpListener::from_std(self.listener).map_err(StudioError::Start)?;
            let shutdown = async move {
                while !stop.is_stopped() {
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                let _ = events.send(Event::Shutdown);
            };
            conn::serve(listener, router, shutdown).await;
            Ok::<(), StudioError>(())
        })?;
        // Connections still open (a page's WebSocket) end with the runtime.
        drop(rt);
        Ok(())
    }
}

//! The WebSocket `/api/ws`: control, arming and the heartbeat (the library's [`Guard`]),
//! telemetry streams decimated to the page's frame rate, long runs with their progress,
//! and jogs. One JSON object per message (`docs/studio.md` lists them). A page's stream
//! is a subscription to the station's one sampling of that bus
//! ([`Station::telemetry`](robobus::station::Station::telemetry)): any number of pages
//! and plots on a bus cost it one sampling.
//!
//! [`Guard`]: robobus::frontend::guard::Guard

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use axum::extract::State;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::response::Response;
use robobus::catalogue::Family;
use robobus::catalogue::telemetry::RecvError;
use robobus::frontend::{Arming, parse};
use robobus::ops::{OpError, StopToken};
use robobus::station::jog::JogRequest;
use serde::Deserialize;
use serde_json::Value;
use tokio::sync::mpsc;

use crate::msg::ToPage;
use crate::{ApiError, App, Event};

/// The most streams one page may hold.
const MAX_STREAMS: usize = 8;
/// The longest text message taken, bytes.
const MAX_MESSAGE: usize = 4 << 20;
/// Messages queued for a page before the oldest telemetry waits.
const OUT_QUEUE: usize = 1024;
/// The most pages connected at once.
pub(crate) const MAX_PAGES: usize = 32;
/// The most runs one page may have going at once.
const MAX_RUNS: usize = 16;

/// A message from the page.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
enum FromPage {
    TakeControl,
    ReleaseControl,
    Arm {
        #[serde(default)]
        control: Option<String>,
    },
    Disarm,
    Heartbeat,
    Subscribe {
        stream: String,
        request: Value,
        rate_hz: f64,
        #[serde(default)]
        fps: Option<f64>,
    },
    Unsubscribe {
        stream: String,
    },
    Run {
        id: u64,
        request: Value,
        #[serde(default)]
        control: Option<String>,
    },
    Stop {
        id: u64,
    },
    Jog {
        #[serde(default)]
        id: Option<u64>,
        family: Family,
        #[serde(default)]
        bus: Option<String>,
        device: u8,
        target: f64,
        #[serde(default)]
        control: Option<String>,
    },
}

/// Whether a message of this page's (`me`) proves control with `given`: the secret this
/// studio gave this very WebSocket (a secret of another connection, a stale or a guessed
/// one is refused, and so is none).
fn proves(app: &App, me: u64, given: Option<&str>) -> Result<(), OpError> {
    let Some(given) = given else {
        return Err(OpError::Refused(
            "this message changes a device and needs `control`: the secret of this page's \
             `control` message (take control first); nothing was sent"
                .into(),
        ));
    };
    match app.prove(given) {
        Ok(session) if session == me => Ok(()),
        Ok(_) => Err(OpError::Refused(
            "this control secret belongs to another connection: a page proves control only \
             with its own; nothing was sent"
                .into(),
        )),
        Err(e) => Err(e),
    }
}

/// The upgrade (its route's gate checked it first: `Host`, `Origin`, the token).
pub(crate) async fn upgrade(
    State(app): State<Arc<App>>,
    ws: WebSocketUpgrade,
) -> Result<Response, ApiError> {
    // Each page costs threads (its streams, its runs): their number is bounded.
    let Some(page) = PageSlot::take(&app) else {
        return Err(ApiError {
            status: axum::http::StatusCode::SERVICE_UNAVAILABLE,
            kind: "refused",
            message: format!("{MAX_PAGES} pages are connected already: close one first"),
            retry_after: None,
        });
    };
    Ok(ws
        .max_message_size(MAX_MESSAGE)
        .on_upgrade(move |socket| session(app, socket, page)))
}

/// A connected page's place among the [`MAX_PAGES`]; given back when dropped.
struct PageSlot(Arc<App>);

impl PageSlot {
    fn take(app: &Arc<App>) -> Option<Self> {
        app.pages
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < MAX_PAGES).then_some(n + 1)
            })
            .ok()
            .map(|_| Self(Arc::clone(app)))
    }
}

impl Drop for PageSlot {
    fn drop(&mut self) {
        self.0.pages.fetch_sub(1, Ordering::AcqRel);
    }
}

/// What one page has going: its runs' stop tokens, and whether a jog is in flight (a page
/// has at most one: jogs that come faster are refused, never queued).
#[derive(Default)]
struct Going {
    runs: std::sync::Mutex<HashMap<u64, StopToken>>,
    jogging: AtomicBool,
}

/// How often a stream's forwarder looks whether it was stopped, at the latest.
const STOP_POLL: Duration = Duration::from_millis(50);

/// One telemetry stream of a page: the flag that stops the thread which forwards its
/// subscription. Dropping it never waits (it runs on the server's one runtime thread):
/// the thread sees the flag within [`STOP_POLL`] and ends on its own, leaving the bus's
/// sampling there (the last subscriber to leave stops it).
struct Stream {
    stop: Arc<AtomicBool>,
}

impl Drop for Stream {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn error_msg(id: Option<u64>, e: &OpError) -> String {
    api_error_msg(id, &ApiError::of(e))
}

fn api_error_msg(id: Option<u64>, a: &ApiError) -> String {
    ToPage::Error {
        id,
        kind: a.kind,
        message: &a.message,
    }
    .text()
}

async fn session(app: Arc<App>, mut socket: WebSocket, _page: PageSlot) {
    let me = app.new_session();
    let (tx, mut rx) = mpsc::channel::<String>(OUT_QUEUE);
    let mut events = app.events.subscribe();
    let mut streams: HashMap<String, Stream> = HashMap::new();
    let going: Arc<Going> = Arc::default();
    let hello = ToPage::Hello {
        read_only: app.admission.read_only(),
        simulated: app.sim.is_some(),
    };
    if socket
        .send(Message::Text(hello.text().into()))
        .await
        .is_err()
    {
        return;
    }
    let _ = tx.try_send(control_msg(&app, me));
    loop {
        tokio::select! {
            incoming = socket.recv() => {
                let Some(Ok(msg)) = incoming else { break };
                let text = match msg {
                    Message::Text(t) => t.to_string(),
                    Message::Close(_) => break,
                    _ => continue,
                };
                handle(&app, me, &text, &tx, &mut streams, &going);
            }
            out = rx.recv() => {
                let Some(out) = out else { break };
                if socket.send(Message::Text(out.into())).await.is_err() {
                    break;
                }
            }
            ev = events.recv() => {
                match ev {
                    Ok(Event::Control) => {
                        let _ = tx.try_send(control_msg(&app, me));
                    }
                    Ok(Event::Message(m)) => {
                        let _ = tx.try_send(m.to_string());
                    }
                    Ok(Event::Shutdown) | Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
                    Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {}
                }
            }
        }
    }
    // The page is gone: its runs stop, its streams end, and if it controlled, the guard
    // brings what it moved to the safe state.
    for t in going
        .runs
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .values()
    {
        t.stop();
    }
    app.forget_secret(me);
    let was_controller = app.guard.view(me).controller;
    app.guard.release_control(me);
    if was_controller {
        let _ = app.events.send(Event::Control);
    }
    drop(streams);
}

/// This page's view of control; the controller's carries its control secret (`secret`),
/// sent only over its own WebSocket.
fn control_msg(app: &App, me: u64) -> String {
    let secret = app.secret_of(me);
    let v = app.guard.view(me);
    ToPage::Control {
        controller: v.controller,
        armed: v.armed,
        held_by_other: v.held_by_other,
        secret,
    }
    .text()
}

fn handle(
    app: &Arc<App>,
    me: u64,
    text: &str,
    tx: &mpsc::Sender<String>,
    streams: &mut HashMap<String, Stream>,
    going: &Arc<Going>,
) {
    let msg: FromPage = match serde_json::from_str(text) {
        Ok(m) => m,
        Err(e) => {
            let e = OpError::invalid("message", "JSON", format!("{e} (see docs/studio.md)"));
            let _ = tx.try_send(error_msg(None, &e));
            return;
        }
    };
    let changed = |r: Result<(), OpError>| match r {
        Ok(()) => {
            let _ = app.events.send(Event::Control);
        }
        Err(e) => {
            let _ = tx.try_send(error_msg(None, &e));
        }
    };
    match msg {
        FromPage::TakeControl => {
            app.guard.take_control(me);
            changed(Ok(()));
        }
        FromPage::ReleaseControl => {
            app.guard.release_control(me);
            changed(Ok(()));
        }
        FromPage::Arm { control } => {
            let r = app
                .admission
                .may_arm()
                .map_err(OpError::from)
                .and_then(|()| proves(app, me, control.as_deref()))
                .and_then(|()| app.guard.arm(me));
            changed(r);
        }
        FromPage::Disarm => changed(app.guard.disarm(me)),
        FromPage::Heartbeat => app.guard.heartbeat(me),
        FromPage::Subscribe {
            stream,
            request,
            rate_hz,
            fps,
        } => {
            if let Err(e) = resubscribe(app, streams, stream, request, rate_hz, fps, tx.clone()) {
                let _ = tx.try_send(error_msg(None, &e));
            }
        }
        FromPage::Unsubscribe { stream } => {
            streams.remove(&stream);
        }
        FromPage::Run {
            id,
            request,
            control,
        } => run(app, me, id, request, control.as_deref(), tx.clone(), going),
        FromPage::Stop { id } => {
            if let Some(t) = going
                .runs
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .get(&id)
            {
                t.stop();
            }
        }
        FromPage::Jog {
            id,
            family,
            bus,
            device,
            target,
            control,
        } => jog(
            app,
            me,
            id,
            control.as_deref(),
            JogRequest {
                family,
                bus,
                device,
                target,
            },
            tx.clone(),
            going,
        ),
    }
}

fn run(
    app: &Arc<App>,
    me: u64,
    id: u64,
    request: Value,
    control: Option<&str>,
    tx: mpsc::Sender<String>,
    going: &Arc<Going>,
) {
    let request = match parse::request_value(request) {
        Ok(r) => r,
        Err(e) => {
            let _ = tx.try_send(error_msg(Some(id), &e));
            return;
        }
    };
    // A change proves control first; a read-only studio says so whatever the proof.
    let proof = if request.effect() == robobus::catalogue::Effect::Read {
        Ok(())
    } else {
        proves(app, me, control)
    };
    let admitted = match proof {
        Err(e) if !app.admission.read_only() => Err(ApiError::of(&e)),
        _ => app.admit(Some(me), request),
    };
    let admitted = match admitted {
        Ok(a) => a,
        Err(e) => {
            let _ = tx.try_send(api_error_msg(Some(id), &e));
            return;
        }
    };
    let token = StopToken::new();
    {
        let mut runs = going
            .runs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if runs.len() >= MAX_RUNS || runs.contains_key(&id) {
            let e = OpError::Refused(format!(
                "run {id}: at most {MAX_RUNS} runs at once per page, each with its own id; \
                 nothing was sent"
            ));
            let _ = tx.try_send(error_msg(Some(id), &e));
            return;
        }
        runs.insert(id, token.clone());
    }
    let app = Arc::clone(app);
    let going = Arc::clone(going);
    tokio::spawn(async move {
        let out = match app.run(admitted, token, Some(tx.clone()), Some(id)).await {
            Ok(report) => ToPage::Report {
                id,
                report: &report,
            }
            .text(),
            Err(e) => error_msg(Some(id), &e),
        };
        going
            .runs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .remove(&id);
        let _ = tx.send(out).await;
    });
}

fn jog(
    app: &Arc<App>,
    me: u64,
    id: Option<u64>,
    control: Option<&str>,
    req: JogRequest,
    tx: mpsc::Sender<String>,
    going: &Arc<Going>,
) {
    // A read-only studio says so whatever the proof.
    let admitted = match proves(app, me, control) {
        Err(e) if !app.admission.read_only() => Err(e),
        _ => app
            .admission
            .admit_jog(
                Arming::Guard {
                    guard: &app.guard,
                    session: Some(me),
                },
                req.family,
                req.bus.as_deref(),
                req.device,
            )
            .map_err(OpError::from),
    };
    if let Err(e) = admitted {
        let _ = tx.try_send(error_msg(id, &e));
        return;
    }
    if going.jogging.swap(true, Ordering::AcqRel) {
        let e = OpError::Refused(
            "a jog of this page is still being sent: this one was dropped (send the next \
             when its `jogged` arrives); nothing was sent"
                .into(),
        );
        let _ = tx.try_send(error_msg(id, &e));
        return;
    }
    let app = Arc::clone(app);
    let going = Arc::clone(going);
    tokio::spawn(async move {
        let worker = Arc::clone(&app);
        let done =
            tokio::task::spawn_blocking(move || worker.jogger.jog(&worker.station, &req)).await;
        let out = match done {
            Ok(Ok(j)) => {
                app.announce(&ToPage::Target {
                    family: j.family,
                    bus: &j.bus,
                    device: u32::from(j.device),
                    value: j.sent,
                    unix_ms: crate::unix_ms(),
                });
                ToPage::Jogged { id, jogged: &j }.text()
            }
            Ok(Err(e)) => error_msg(id, &e),
            Err(e) => error_msg(
                id,
                &OpError::Device(format!("the jog's thread failed: {e}")),
            ),
        };
        going.jogging.store(false, Ordering::Release);
        let _ = tx.send(out).await;
    });
}

/// (Re)starts a page's stream `name` (the one it replaces stops by itself).
fn resubscribe(
    app: &Arc<App>,
    streams: &mut HashMap<String, Stream>,
    name: String,
    request: Value,
    rate_hz: f64,
    fps: Option<f64>,
    tx: mpsc::Sender<String>,
) -> Result<(), OpError> {
    if streams.len() >= MAX_STREAMS && !streams.contains_key(&name) {
        return Err(OpError::invalid(
            "stream",
            robobus::ops::cut(&name),
            format!("at most {MAX_STREAMS} streams per page: unsubscribe one first"),
        ));
    }
    streams.remove(&name);
    let s = subscribe(app, &name, request, rate_hz, fps, tx)?;
    streams.insert(name, s);
    Ok(())
}

/// Subscribes to the bus's shared sampling and starts the forwarder: the latest sample
/// at most `fps` times a second, with how many were skipped since the previous one.
fn subscribe(
    app: &Arc<App>,
    name: &str,
    request: Value,
    rate_hz: f64,
    fps: Option<f64>,
    tx: mpsc::Sender<String>,
) -> Result<Stream, OpError> {
    let request = parse::request_value(request)?;
    let fps = fps.unwrap_or(30.0);
    if !(1.0..=120.0).contains(&fps) {
        return Err(OpError::invalid("fps", fps, "allowed: 1..=120"));
    }
    let sub = app.station.telemetry(request, rate_hz, 64)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    let name = name.to_owned();
    let frame = Duration::from_secs_f64(1.0 / fps);
    std::thread::Builder::new()
        .name("studio-stream".into())
        .spawn(move || {
            let mut next = Instant::now();
            let mut latest = None;
            let mut skipped = 0u64;
            while !flag.load(Ordering::Relaxed) {
                let wait = next
                    .saturating_duration_since(Instant::now())
                    .min(STOP_POLL);
                match sub.recv_timeout(wait.max(Duration::from_millis(1))) {
                    Ok(d) => {
                        skipped += d.lost + u64::from(latest.is_some());
                        latest = Some(d.sample);
                    }
                    Err(RecvError::Ended) => break,
                    Err(RecvError::Timeout) => {}
                }
                if Instant::now() >= next {
                    next = Instant::now() + frame;
                    if let Some(s) = latest.take() {
                        let msg = ToPage::Telemetry {
                            stream: &name,
                            sample: &s,
                            skipped,
                        }
                        .text();
                        skipped = 0;
                        if tx.blocking_send(msg).is_err() {
                            break;
                        }
                    }
                }
            }
        })
        .map_err(|e| OpError::Device(format!("starting a telemetry stream: {e}")))?;
    Ok(Stream { stop })
}

//! The queryables (`NS/robobus/run`, `plan`, `arm` and, on the built-in simulated robot,
//! `sim`): a bounded queue and two workers that parse, admit and answer each query in
//! JSON, and the replies and errors every queryable of the bridge sends.

use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use robobus::frontend::{PlanView, parse};
use robobus::ops::{OpError, StopToken};
use robobus::station::follow::Follower;
use zenoh::Wait as _;
use zenoh::bytes::Encoding;
use zenoh::query::Query;

use crate::{BridgeError, MAX_REQUEST, QUERY_QUEUE, Shared, bump, spawn, zerr};

/// The queryables: a bounded queue and two workers (a long operation does not stall the
/// others; more than the queue holds is answered busy). Their threads.
pub(crate) fn declare_queries(
    shared: &Arc<Shared>,
    session: &zenoh::Session,
    declared: &mut Vec<Box<dyn std::any::Any + Send>>,
) -> Result<Vec<JoinHandle<()>>, BridgeError> {
    let keys = &shared.keys;
    let mut threads = Vec::new();
    let (tx, rx) = std::sync::mpsc::sync_channel::<(QueryKind, Query)>(QUERY_QUEUE);
    let rx = Arc::new(Mutex::new(rx));
    for (key, kind) in [
        (&keys.run, QueryKind::Run),
        (&keys.plan, QueryKind::Plan),
        (&keys.arm, QueryKind::Arm),
    ]
    .into_iter()
    .chain(shared.sim.is_some().then_some((&keys.sim, QueryKind::Sim)))
    {
        let tx = tx.clone();
        let s = Arc::clone(shared);
        let q = session
            .declare_queryable(key.clone())
            .callback(move |query| {
                bump(&s.counters.queries);
                if let Err(std::sync::mpsc::TrySendError::Full((_, query))) =
                    tx.try_send((kind, query))
                {
                    bump(&s.counters.queries_refused);
                    reply_error(
                        &query,
                        "refused",
                        &format!(
                            "the bridge is busy: {QUERY_QUEUE} queries are waiting; \
                             nothing was run"
                        ),
                    );
                }
            })
            .wait()
            .map_err(zerr)?;
        declared.push(Box::new(q));
    }
    drop(tx);
    for n in 0..2 {
        let s = Arc::clone(shared);
        let rx = Arc::clone(&rx);
        threads.push(spawn(&format!("robobus-query-{n}"), move || {
            // Until the bridge stops, whether or not Zenoh has dropped the callbacks
            // that hold the queue's senders by then.
            while !s.stop.is_stopped() {
                let next = rx
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .recv_timeout(Duration::from_millis(50));
                match next {
                    Ok((kind, query)) => answer(&s, kind, &query),
                    Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                    Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return,
                }
            }
        })?);
    }

    Ok(threads)
}

#[derive(Debug, Clone, Copy)]
enum QueryKind {
    Run,
    Plan,
    Arm,
    Sim,
}

pub(crate) fn reply_json(query: &Query, value: &serde_json::Value) {
    let _ = query
        .reply(query.key_expr().clone(), value.to_string())
        .encoding(Encoding::APPLICATION_JSON)
        .wait();
}

/// An error reply: the kind's name and the message.
#[derive(Debug, serde::Serialize)]
struct ErrorReply<'a> {
    kind: &'a str,
    message: &'a str,
}

/// The reply of `robobus/arm`: the state, and the joints of a command in order.
#[derive(Debug, serde::Serialize)]
struct ArmReply<'a> {
    armed: bool,
    joints: Option<&'a [robobus::station::follow::FollowedJoint]>,
}

pub(crate) fn reply_error(query: &Query, kind: &str, message: &str) {
    let body = serde_json::to_string(&ErrorReply { kind, message }).unwrap_or_default();
    let _ = query
        .reply_err(body)
        .encoding(Encoding::APPLICATION_JSON)
        .wait();
}

pub(crate) fn reply_op_error(query: &Query, e: &OpError) {
    reply_error(query, e.kind().name(), &e.to_string());
}

/// The query's payload as text, bounded.
pub(crate) fn query_text(query: &Query) -> Result<String, OpError> {
    let Some(p) = query.payload() else {
        return Ok(String::new());
    };
    if p.len() > MAX_REQUEST {
        return Err(OpError::invalid(
            "payload",
            format!("{} bytes", p.len()),
            format!("at most {MAX_REQUEST} bytes"),
        ));
    }
    p.try_to_string()
        .map(std::borrow::Cow::into_owned)
        .map_err(|e| OpError::invalid("payload", "bytes", format!("UTF-8 JSON text ({e})")))
}

fn answer(s: &Shared, kind: QueryKind, query: &Query) {
    let text = match query_text(query) {
        Ok(t) => t,
        Err(e) => return reply_op_error(query, &e),
    };
    let result = match kind {
        QueryKind::Run => run_request(s, &text),
        QueryKind::Plan => parse::request_text(&text)
            .and_then(|r| PlanView::of(&r))
            .map(|v| v.to_value()),
        QueryKind::Arm => arm(s, &text),
        QueryKind::Sim => Ok(s
            .sim
            .as_ref()
            .map(|sim| serde_json::to_value(sim.snapshot()).unwrap_or_default())
            .unwrap_or_default()),
    };
    match result {
        Ok(v) => reply_json(query, &v),
        Err(e) => reply_op_error(query, &e),
    }
}

/// One request of `robobus/run`: parsed, admitted (read-only, arming, the write rate),
/// run.
pub(crate) fn run_request(s: &Shared, text: &str) -> Result<serde_json::Value, OpError> {
    let request = parse::request_text(text)?;
    let request = s.admission.admit(s.arming(), request)?.into_request();
    let token = StopToken::new();
    let _ticket = s.guard.running(&token);
    let mut control = robobus::ops::Control::new(&token);
    let report = robobus::catalogue::run(&s.station, &request, &mut control)?;
    Ok(serde_json::to_value(report).unwrap_or_default())
}

fn arm(s: &Shared, text: &str) -> Result<serde_json::Value, OpError> {
    let t = text.trim();
    let want = match t {
        "" => None,
        "true" => Some(true),
        "false" => Some(false),
        _ => Some(
            serde_json::from_str::<serde_json::Value>(t)
                .ok()
                .and_then(|v| v.get("armed").and_then(serde_json::Value::as_bool))
                .ok_or_else(|| {
                    OpError::invalid(
                        "arm",
                        robobus::ops::cut(t),
                        "true, false, {\"armed\": true|false}, or nothing to read the state",
                    )
                })?,
        ),
    };
    if let Some(a) = want {
        s.set_armed(a)?;
    }
    Ok(serde_json::to_value(ArmReply {
        armed: s.armed(),
        joints: s.follower.as_ref().map(Follower::joints),
    })
    .unwrap_or_default())
}

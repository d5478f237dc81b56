//! The studio's connections: accepted, bounded and timed out here (axum only routes).
//!
//! - A client has [`HEADER_TIMEOUT`] to send a request's headers, on a new connection and
//!   between two requests of a kept-alive one: an idle or slowly-sending connection is
//!   closed then. A request body has [`BODY_TIMEOUT`] (408 past it).
//! - At most [`MAX_CONNECTIONS`] HTTP connections are open at once (a page's WebSocket,
//!   once upgraded, counts among the pages instead). A new one beyond it takes the place
//!   of the connection idle the longest (one not in a request), which is closed; when
//!   every connection is in a request, the new one is answered 503 and closed.
//! - Accepting never stops the runtime: running out of file descriptors waits a moment
//!   and tries again.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::AsyncWriteExt as _;
use tokio::sync::{Notify, watch};

/// The longest time to send a request's headers (also the idle time of a connection
/// between two requests).
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// The longest time to send a request's body.
pub const BODY_TIMEOUT: Duration = Duration::from_secs(30);
/// The most HTTP connections open at once.
pub const MAX_CONNECTIONS: usize = 128;
/// How long in-flight requests may take to finish once the studio stops.
const DRAIN: Duration = Duration::from_secs(5);

/// One open connection: whether it is in a request, since when it is idle, and how to
/// close it.
struct Conn {
    busy: AtomicUsize,
    idle_since: Mutex<Instant>,
    close: Notify,
}

/// The open connections.
#[derive(Default)]
struct Conns {
    open: Mutex<HashMap<u64, Arc<Conn>>>,
    next: AtomicU64,
}

impl Conns {
    /// A place for a new connection: free, or the longest-idle connection's (closed);
    /// `None` when every connection is in a request.
    fn admit(&self) -> Option<(u64, Arc<Conn>)> {
        let mut open = self.open.lock().unwrap_or_else(PoisonError::into_inner);
        if open.len() >= MAX_CONNECTIONS {
            let oldest = open
                .iter()
                .filter(|(_, c)| c.busy.load(Ordering::Acquire) == 0)
                .min_by_key(|(_, c)| *c.idle_since.lock().unwrap_or_else(PoisonError::into_inner))
                .map(|(id, _)| *id)?;
            if let Some(c) = open.remove(&oldest) {
                c.close.notify_one();
            }
        }
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let conn = Arc::new(Conn {
            busy: AtomicUsize::new(0),
            idle_since: Mutex::new(Instant::now()),
            close: Notify::new(),
        });
        open.insert(id, Arc::clone(&conn));
        Some((id, conn))
    }

    fn remove(&self, id: u64) {
        self.open
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .remove(&id);
    }

    fn is_empty(&self) -> bool {
        self.open
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .is_empty()
    }
}

/// The answer to a connection over the cap.
fn busy_answer() -> Vec<u8> {
    let body = format!(
        "{{\"kind\":\"refused\",\"message\":\"the studio has {MAX_CONNECTIONS} connections \
         in requests already: try again in a moment\"}}"
    );
    format!(
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nConnection: \
         close\r\nRetry-After: 1\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

/// Serves `router` on `listener` until `shutdown` resolves; then lets in-flight requests
/// finish (at most [`DRAIN`]).
pub(crate) async fn serve(
    listener: tokio::net::TcpListener,
    router: Router,
    shutdown: impl std::future::Future<Output = ()>,
) {
    let conns = Arc::new(Conns::default());
    let (stopping, stop_rx) = watch::channel(false);
    let service = TowerToHyperService::new(router);
    tokio::pin!(shutdown);
    loop {
        let tcp = tokio::select! {
            () = &mut shutdown => break,
            accepted = listener.accept() => match accepted {
                Ok((tcp, _)) => tcp,
                Err(e) => {
                    // Out of file descriptors (or a connection reset before it was
                    // taken): wait a moment instead of spinning.
                    tracing::debug!("accept: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
        };
        // Telemetry is many small messages to a page that only reads: without
        // TCP_NODELAY each would wait for the previous one's delayed ACK (up to 40 ms).
        let _ = tcp.set_nodelay(true);
        let Some((id, conn)) = conns.admit() else {
            tokio::spawn(async move {
                let mut tcp = tcp;
                let _ = tokio::time::timeout(Duration::from_secs(1), tcp.write_all(&busy_answer()))
                    .await;
            });
            continue;
        };
        let conns = Arc::clone(&conns);
        let service = service.clone();
        let mut stop_rx = stop_rx.clone();
        tokio::spawn(async move {
            let tracked = Arc::clone(&conn);
            let svc = hyper::service::service_fn(move |req: hyper::Request<Incoming>| {
                let call = hyper::service::Service::call(&service, req);
                let conn = Arc::clone(&tracked);
                conn.busy.fetch_add(1, Ordering::AcqRel);
                async move {
                    let out = call.await;
                    *conn
                        .idle_since
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner) = Instant::now();
                    conn.busy.fetch_sub(1, Ordering::AcqRel);
                    out
                }
            });
            let mut builder = hyper::server::conn::http1::Builder::new();
            builder
                .timer(TokioTimer::new())
                .header_read_timeout(HEADER_TIMEOUT);
            let served = builder
                .serve_connection(TokioIo::new(tcp), svc)
                .with_upgrades();
            tokio::pin!(served);
            tokio::select! {
                _ = served.as_mut() => {}
                () = conn.close.notified() => {}
                () = async { drop(stop_rx.wait_for(|s| *s).await) } => {
                    served.as_mut().graceful_shutdown();
                    let _ = tokio::time::timeout(DRAIN, served.as_mut()).await;
                }
            }
            conns.remove(id);
        });
    }
    let _ = stopping.send(true);
    let deadline = Instant::now() + DRAIN;
    while !conns.is_empty() && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn over_the_cap_the_longest_idle_connection_gives_way_and_none_in_a_request_does() {
        let conns = Conns::default();
        let mut all: Vec<_> = (0..MAX_CONNECTIONS)
            .map(|_| conns.admit().unwrap())
            .collect();
        // Every one in a request: a new connection is refused.
        for (_, c) in &all {
            c.busy.store(1, Ordering::Release);
        }
        assert!(conns.admit().is_none());
        // Two idle ones: the one idle the longer is closed for the new one.
        let now = Instant::now();
        for (i, when) in [(7, now + Duration::from_secs(2)), (9, now)] {
            all[i].1.busy.store(0, Ordering::Release);
            *all[i].1.idle_since.lock().unwrap() = when;
        }
        let (new, _) = conns.admit().unwrap();
        let open = conns.open.lock().unwrap();
        assert_eq!(open.len(), MAX_CONNECTIONS);
        assert!(!open.contains_key(&all[9].0), "the longest idle was closed");
        assert!(open.contains_key(&all[7].0) && open.contains_key(&new));
        drop(open);
        // It was told to close: its `notified` completes at once.
        let closed = all.swap_remove(9).1;
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async {
            tokio::time::timeout(Duration::from_secs(1), closed.close.notified())
                .await
                .unwrap();
        });
    }
}

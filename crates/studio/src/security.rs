//! Who may talk to the studio: the `Host` of every request (against DNS rebinding), the
//! `Origin` of every state-changing request and of the WebSocket (against other sites'
//! pages), and the token of a studio that listens beyond loopback.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;

use axum::extract::{Query, Request, State};
use axum::http::HeaderMap;
use axum::http::header::{AUTHORIZATION, HOST, ORIGIN};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use crate::{ApiError, App};

/// What a route serves, and so what its requests must carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Access {
    /// The page's own files: `Host` only (the page must load to ask for the token).
    Page,
    /// An API read: `Host` and the token.
    Read,
    /// A state-changing API request: `Host`, `Origin` when present, and the token.
    Change,
    /// The WebSocket: as [`Access::Change`], the token also as `?token=`.
    Socket,
}

/// The gate of one group of routes, as a layer: every route of the group is checked
/// before its handler runs, so no handler can forget it.
pub(crate) async fn layer(
    State((app, access)): State<(Arc<App>, Access)>,
    request: Request,
    next: Next,
) -> Response {
    let query = Query::<HashMap<String, String>>::try_from_uri(request.uri())
        .map(|q| q.0)
        .unwrap_or_default();
    match app.gate.check(
        request.headers(),
        access,
        query.get("token").map(String::as_str),
    ) {
        Ok(()) => next.run(request).await,
        Err(e) => e.into_response(),
    }
}

/// What a request must carry.
#[derive(Debug, Clone)]
pub(crate) struct Gate {
    /// `Host` values that name this server (lower case).
    hosts: Vec<String>,
    /// The token every API request carries, if the studio has one.
    token: Option<String>,
    /// The port it listens on.
    port: u16,
}

impl Gate {
    /// The gate of a server bound to `addr` (also reachable as `localhost` on loopback).
    pub(crate) fn new(addr: SocketAddr, token: Option<String>) -> Self {
        let port = addr.port();
        let mut hosts = vec![addr.to_string().to_lowercase()];
        if addr.ip().is_loopback() {
            hosts.push(format!("localhost:{port}"));
            hosts.push(format!("127.0.0.1:{port}"));
            hosts.push(format!("[::1]:{port}"));
        }
        hosts.sort();
        hosts.dedup();
        Self { hosts, token, port }
    }

    /// Whether `host` (a `Host` header) names this server. Without a token, only its own
    /// address (and loopback's names): a page whose DNS name was rebound to this machine is
    /// refused. With a token, which such a page cannot know, any name at this port: the
    /// one the client really used to reach a `0.0.0.0` or a named address.
    fn host_ok(&self, host: &str) -> bool {
        if self.hosts.iter().any(|a| a.eq_ignore_ascii_case(host)) {
            return true;
        }
        self.token.is_some() && port_of(host) == Some(self.port)
    }

    /// The addresses a page may be served from (`http://HOST`): this server's names, and
    /// with a token the very name the request was sent to (the page's own origin).
    fn origin_ok(&self, origin: &str, host: &str) -> bool {
        origin.strip_prefix("http://").is_some_and(|h| {
            self.hosts.iter().any(|a| a.eq_ignore_ascii_case(h))
                || (self.token.is_some() && h.eq_ignore_ascii_case(host))
        })
    }

    /// Checks `Host` (always), `Origin` (when present on a state-changing request or the
    /// WebSocket), and the token of an API request (`token_query`: a WebSocket's
    /// `?token=`).
    pub(crate) fn check(
        &self,
        headers: &HeaderMap,
        access: Access,
        token_query: Option<&str>,
    ) -> Result<(), ApiError> {
        let changes = matches!(access, Access::Change | Access::Socket);
        let api = access != Access::Page;
        let token_query = if access == Access::Socket {
            token_query
        } else {
            None
        };
        let host = headers
            .get(HOST)
            .and_then(|h| h.to_str().ok())
            .unwrap_or("");
        if !self.host_ok(host) {
            let allowed = if self.token.is_some() {
                format!("any name with the port {}", self.port)
            } else {
                self.hosts.join(", ")
            };
            return Err(ApiError::forbidden(format!(
                "Host {:?} is not this studio's address (allowed: {allowed}): refused against \
                 DNS rebinding",
                robobus::ops::cut(host),
            )));
        }
        if changes && let Some(origin) = headers.get(ORIGIN) {
            let origin = origin.to_str().unwrap_or("");
            if !self.origin_ok(origin, host) {
                return Err(ApiError::forbidden(format!(
                    "Origin {:?} is not this studio's page (allowed: http://{}): requests \
                     from other sites are refused",
                    robobus::ops::cut(origin),
                    self.hosts.join(", http://")
                )));
            }
        }
        if api && let Some(token) = &self.token {
            let bearer = headers
                .get(AUTHORIZATION)
                .and_then(|h| h.to_str().ok())
                .and_then(|h| h.strip_prefix("Bearer "));
            let given = bearer.or(token_query).unwrap_or("");
            if !same(given.as_bytes(), token.as_bytes()) {
                return Err(ApiError::unauthorized(
                    "this studio needs its token: `Authorization: Bearer TOKEN` (WebSocket: \
                     ?token=TOKEN; the page: open http://HOST:PORT/#token=TOKEN)",
                ));
            }
        }
        Ok(())
    }
}

/// The port a `Host` value names (`name:PORT`, `[v6]:PORT`; none: 80).
fn port_of(host: &str) -> Option<u16> {
    let after_v6 = host.rfind(']').map_or(host, |i| &host[i + 1..]);
    match after_v6.rsplit_once(':') {
        Some((_, port)) => port.parse().ok(),
        None if !host.is_empty() => Some(80),
        None => None,
    }
}

/// A page's control secret: 256 bits from the operating system's random source.
pub(crate) struct Secret([u8; 32]);

impl Secret {
    /// A fresh secret; `None` if the system's random source fails (no control is given).
    pub(crate) fn new() -> Option<Self> {
        let mut bytes = [0u8; 32];
        getrandom::fill(&mut bytes).ok()?;
        Some(Self(bytes))
    }

    /// As the page sends it: 64 lower-case hex digits.
    pub(crate) fn to_hex(&self) -> String {
        use std::fmt::Write as _;
        self.0.iter().fold(String::with_capacity(64), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
    }

    /// Whether `given` is this secret (in constant time for a given length).
    pub(crate) fn matches(&self, given: &str) -> bool {
        same(given.as_bytes(), self.to_hex().as_bytes())
    }
}

/// Compares in time independent of where the first difference is.
fn same(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn headers(host: &str, origin: Option<&str>, auth: Option<&str>) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(HOST, HeaderValue::from_str(host).unwrap());
        if let Some(o) = origin {
            h.insert(ORIGIN, HeaderValue::from_str(o).unwrap());
        }
        if let Some(a) = auth {
            h.insert(AUTHORIZATION, HeaderValue::from_str(a).unwrap());
        }
        h
    }

    #[test]
    fn host_origin_and_token() {
        let g = Gate::new("127.0.0.1:8000".parse().unwrap(), None);
        assert!(
            g.check(&headers("127.0.0.1:8000", None, None), Access::Change, None)
                .is_ok()
        );
        assert!(
            g.check(&headers("localhost:8000", None, None), Access::Change, None)
                .is_ok()
        );
        let e = g
            .check(
                &headers("evil.example:8000", None, None),
                Access::Read,
                None,
            )
            .unwrap_err();
        assert_eq!(e.status.as_u16(), 403);
        let foreign = headers("127.0.0.1:8000", Some("http://evil.example"), None);
        assert_eq!(
            g.check(&foreign, Access::Change, None)
                .unwrap_err()
                .status
                .as_u16(),
            403
        );
        // A read does not need its Origin checked (a plain GET from another site cannot
        // read the answer without CORS headers, which the studio never sends).
        assert!(g.check(&foreign, Access::Read, None).is_ok());
        let own = headers("127.0.0.1:8000", Some("http://localhost:8000"), None);
        assert!(g.check(&own, Access::Change, None).is_ok());

        let g = Gate::new("10.0.0.2:9000".parse().unwrap(), Some("s3cret".into()));
        let h = headers("10.0.0.2:9000", None, None);
        assert_eq!(
            g.check(&h, Access::Read, None).unwrap_err().status.as_u16(),
            401
        );
        assert!(
            g.check(&h, Access::Page, None).is_ok(),
            "static files need no token"
        );
        assert!(g.check(&h, Access::Socket, Some("s3cret")).is_ok());
        // `?token=` is the WebSocket's only: an API request carries the header.
        assert_eq!(
            g.check(&h, Access::Read, Some("s3cret"))
                .unwrap_err()
                .status
                .as_u16(),
            401
        );
        let h = headers("10.0.0.2:9000", None, Some("Bearer s3cret"));
        assert!(g.check(&h, Access::Change, None).is_ok());
        let h = headers("10.0.0.2:9000", None, Some("Bearer s3cre"));
        assert_eq!(
            g.check(&h, Access::Change, None)
                .unwrap_err()
                .status
                .as_u16(),
            401
        );
        // With a token, the name the client used at this port (the token is the proof):
        // a studio on 0.0.0.0 reached as localhost, 127.0.0.1 or its host name.
        for host in ["localhost:9000", "127.0.0.1:9000", "robot-pc.lan:9000"] {
            let h = headers(host, Some(&format!("http://{host}")), Some("Bearer s3cret"));
            assert!(g.check(&h, Access::Change, None).is_ok(), "{host}");
        }
        // Not another port, and not another site's page.
        let h = headers("localhost:9001", None, Some("Bearer s3cret"));
        assert_eq!(
            g.check(&h, Access::Change, None)
                .unwrap_err()
                .status
                .as_u16(),
            403
        );
        let h = headers(
            "localhost:9000",
            Some("http://evil.example"),
            Some("Bearer s3cret"),
        );
        assert_eq!(
            g.check(&h, Access::Change, None)
                .unwrap_err()
                .status
                .as_u16(),
            403
        );
        assert_eq!(port_of("[::1]:7480"), Some(7480));
        assert_eq!(port_of("robot-pc"), Some(80));
        assert_eq!(port_of(""), None);
    }
}

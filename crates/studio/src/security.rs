//! Who may talk to the studio: the `Host` of every request (against DNS rebinding), the
//! `Origin` of every state-changing request and of the WebSocket (against other sites'
//! pages), and the token of a studio that listens beyond loopback.

use std::net::SocketAddr;

use axum::http::HeaderMap;
use axum::http::header::{AUTHORIZATION, HOST, ORIGIN};

use crate::ApiError;

/// What a request must carry.
#[derive(Debug, Clone)]
pub(crate) struct Gate {
    /// `Host` values that name this server (lower case).
    hosts: Vec<String>,
    /// The token every API request carries, if the studio has one.
    token: Option<String>,
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
        Self { hosts, token }
    }

    /// The addresses a page may be served from (`http://HOST`).
    fn origin_ok(&self, origin: &str) -> bool {
        origin
            .strip_prefix("http://")
            .is_some_and(|h| self.hosts.iter().any(|a| a.eq_ignore_ascii_case(h)))
    }

    /// Checks `Host` (always), `Origin` (when `changes` or it is present on a WebSocket),
    /// and the token of an API request (`token_query`: a WebSocket's `?token=`).
    pub(crate) fn check(
        &self,
        headers: &HeaderMap,
        changes: bool,
        api: bool,
        token_query: Option<&str>,
    ) -> Result<(), ApiError> {
        let host = headers
            .get(HOST)
            .and_then(|h| h.to_str().ok())
            .unwrap_or("");
        if !self.hosts.iter().any(|a| a.eq_ignore_ascii_case(host)) {
            return Err(ApiError::forbidden(format!(
                "Host {:?} is not this studio's address (allowed: {}): refused against DNS \
                 rebinding",
                robobus::ops::cut(host),
                self.hosts.join(", ")
            )));
        }
        if changes && let Some(origin) = headers.get(ORIGIN) {
            let origin = origin.to_str().unwrap_or("");
            if !self.origin_ok(origin) {
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
            g.check(&headers("127.0.0.1:8000", None, None), true, true, None)
                .is_ok()
        );
        assert!(
            g.check(&headers("localhost:8000", None, None), true, true, None)
                .is_ok()
        );
        let e = g
            .check(&headers("evil.example:8000", None, None), false, true, None)
            .unwrap_err();
        assert_eq!(e.status.as_u16(), 403);
        let foreign = headers("127.0.0.1:8000", Some("http://evil.example"), None);
        assert_eq!(
            g.check(&foreign, true, true, None)
                .unwrap_err()
                .status
                .as_u16(),
            403
        );
        // A read does not need its Origin checked (a plain GET from another site cannot
        // read the answer without CORS headers, which the studio never sends).
        assert!(g.check(&foreign, false, true, None).is_ok());
        let own = headers("127.0.0.1:8000", Some("http://localhost:8000"), None);
        assert!(g.check(&own, true, true, None).is_ok());

        let g = Gate::new("10.0.0.2:9000".parse().unwrap(), Some("s3cret".into()));
        let h = headers("10.0.0.2:9000", None, None);
        assert_eq!(
            g.check(&h, false, true, None).unwrap_err().status.as_u16(),
            401
        );
        assert!(
            g.check(&h, false, false, None).is_ok(),
            "static files need no token"
        );
        assert!(g.check(&h, false, true, Some("s3cret")).is_ok());
        let h = headers("10.0.0.2:9000", None, Some("Bearer s3cret"));
        assert!(g.check(&h, true, true, None).is_ok());
        let h = headers("10.0.0.2:9000", None, Some("Bearer s3cre"));
        assert_eq!(
            g.check(&h, true, true, None).unwrap_err().status.as_u16(),
            401
        );
        // Loopback names are not accepted for a non-loopback address.
        let h = headers("localhost:9000", None, Some("Bearer s3cret"));
        assert_eq!(
            g.check(&h, true, true, None).unwrap_err().status.as_u16(),
            403
        );
    }
}

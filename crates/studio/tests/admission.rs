//! The studio's admission through its HTTP API: the library's one admission (the write
//! rate, arming, read-only), the one parser's wording, the one plan view, and the gate
//! on every group of routes.

#![allow(clippy::unwrap_used)] // test helpers: a failed unwrap is a failed test

use std::io::{Read as _, Write as _};
use std::net::TcpStream;
use std::time::Duration;

use robobus::frontend::guard::GuardConfig;
use robobus::ops::StopToken;
use robobus::station::Station;
use robobus_studio::{Studio, StudioConfig};
use serde_json::Value;

struct Running {
    addr: String,
    stop: StopToken,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Running {
    fn drop(&mut self) {
        self.stop.stop();
        if let Some(t) = self.thread.take() {
            t.join().unwrap();
        }
    }
}

fn studio(read_only: bool) -> Running {
    let studio = Studio::bind(
        Station::simulated().unwrap(),
        None,
        StudioConfig {
            listen: "127.0.0.1:0".parse().unwrap(),
            token: None,
            read_only,
            guard: GuardConfig::default(),
        },
    )
    .unwrap();
    let addr = studio.addr().to_string();
    let stop = StopToken::new();
    let s = stop.clone();
    let thread = std::thread::spawn(move || studio.serve(&s).unwrap());
    Running {
        addr,
        stop,
        thread: Some(thread),
    }
}

/// Status, headers (lower case) and body of one request.
fn http(
    addr: &str,
    method: &str,
    path: &str,
    host: Option<&str>,
    body: &str,
) -> (u16, String, Value) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let host = host.unwrap_or(addr);
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    let status = out[9..12].parse().unwrap();
    let (head, body) = out.split_once("\r\n\r\n").unwrap();
    let start = body.find(['{', '[']).unwrap_or(0);
    let end = body.rfind(['}', ']']).map_or(body.len(), |e| e + 1);
    let json = serde_json::from_str(&body[start..end.max(start)]).unwrap_or(Value::Null);
    (status, head.to_lowercase(), json)
}

const WRITE: &str = r#"{"op":"wck.set","id":0,"param":"gains","p":20,"d":30,"confirm":true}"#;
const MOVE: &str = r#"{"op":"whj.move","joint":3,"degrees":10}"#;

#[test]
fn the_write_rate_and_arming_hold_as_the_one_admission_words_them() {
    let s = studio(false);
    for n in 1..=10 {
        let (status, _, body) = http(&s.addr, "POST", "/api/run", None, WRITE);
        assert_eq!(status, 200, "write {n}: {body}");
    }
    let (status, head, body) = http(&s.addr, "POST", "/api/run", None, WRITE);
    assert_eq!(status, 429, "{body}");
    assert!(head.contains("\r\nretry-after: "), "{head}");
    assert_eq!(body["kind"], "rate-limited");
    let m = body["message"].as_str().unwrap();
    assert!(
        m.starts_with(
            "wck.set: at most 10 EEPROM / flash / ID writes a minute (they wear the device's \
             memory); try again in "
        ),
        "{m}"
    );
    // A move from a client that holds no armed control: refused, nothing sent.
    let (status, _, body) = http(&s.addr, "POST", "/api/run", None, MOVE);
    assert_eq!(status, 409, "{body}");
    assert_eq!(body["kind"], "refused");
    assert_eq!(
        body["message"],
        "whj.move: not armed: motion needs this studio armed (take control and arm first); \
         nothing was sent"
    );
}

#[test]
fn a_read_only_studio_runs_reads_only() {
    let s = studio(true);
    let (status, _, body) = http(
        &s.addr,
        "POST",
        "/api/run",
        None,
        r#"{"op":"wck.status","ids":"0"}"#,
    );
    assert_eq!(status, 200, "{body}");
    let (status, _, body) = http(&s.addr, "POST", "/api/run", None, WRITE);
    assert_eq!(status, 409, "{body}");
    assert_eq!(
        body["message"],
        "wck.set: this studio is read-only (started with --read-only): only reading requests \
         run; nothing was sent"
    );
}

#[test]
fn a_bad_request_is_refused_in_the_one_wording() {
    let s = studio(false);
    let (status, _, body) = http(
        &s.addr,
        "POST",
        "/api/run",
        None,
        r#"{"op":"wck.status","ids":"0","colour":"red"}"#,
    );
    assert_eq!(status, 400, "{body}");
    assert_eq!(body["kind"], "bad-input");
    let m = body["message"].as_str().unwrap();
    assert!(m.starts_with("request JSON: unknown field `colour`"), "{m}");
    assert!(
        m.ends_with(
            "(one request object, as the request schema (`robobus schema`) describes); \
             nothing was sent"
        ),
        "{m}"
    );
}

#[test]
fn the_plan_is_the_one_plan_view() {
    let s = studio(false);
    let request = r#"{"op":"whj.save","joints":"4"}"#;
    let (status, _, body) = http(&s.addr, "POST", "/api/plan", None, request);
    assert_eq!(status, 200, "{body}");
    let r = robobus::frontend::parse::request_text(request).unwrap();
    assert_eq!(
        body,
        robobus::frontend::PlanView::of(&r).unwrap().to_value()
    );
    assert_eq!(body["effect"], "configure");
    assert!(body["ask"].is_string(), "{body}");
}

#[test]
fn every_group_of_routes_is_behind_the_gate() {
    let s = studio(false);
    for (method, path) in [
        ("GET", "/"),
        ("GET", "/static/app.js"),
        ("GET", "/api/info"),
        ("GET", "/api/schema"),
        ("GET", "/api/capture"),
        ("GET", "/api/sim"),
        ("POST", "/api/run"),
        ("POST", "/api/plan"),
        ("GET", "/api/ws"),
    ] {
        let (status, _, body) = http(&s.addr, method, path, Some("evil.example:80"), "{}");
        assert_eq!(status, 403, "{method} {path}: {body}");
        assert_eq!(body["kind"], "forbidden", "{method} {path}");
    }
    let (status, _, _) = http(&s.addr, "GET", "/api/info", None, "");
    assert_eq!(status, 200);
}

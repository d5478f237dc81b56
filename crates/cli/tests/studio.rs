//! `robobus studio` as a process: its HTTP API against `robobus run`, who it refuses
//! (Host, Origin, token, non-loopback without a token), and the dead man's switch on the
//! simulators' own state (`GET /api/sim`). The page itself is tested in Chromium
//! (`scripts/studio/test-browser`).

#![allow(clippy::unwrap_used, clippy::panic, clippy::result_large_err)] // test helpers: a failed unwrap is a failed test

use std::fmt::Write as _;
use std::io::{BufRead as _, BufReader, Read as _, Write as _};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

struct Studio {
    child: Child,
    addr: String,
}

impl Drop for Studio {
    /// Stopped as Ctrl-C does (so it removes its capture folder), killed if it does not.
    fn drop(&mut self) {
        if !matches!(self.child.try_wait(), Ok(None)) {
            return; // ended already (and reaped: its pid is no longer ours to signal)
        }
        let pid = self.child.id().to_string();
        let _ = Command::new("kill").args(["-INT", &pid]).status();
        let deadline = Instant::now() + Duration::from_secs(10);
        while matches!(self.child.try_wait(), Ok(None)) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start(args: &[&str]) -> Studio {
    start_in(args, &std::env::temp_dir())
}

/// A studio whose temporary folder (`TMPDIR`) is `tmp`.
fn start_in(args: &[&str], tmp: &std::path::Path) -> Studio {
    let child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .env("TMPDIR", tmp)
        .arg("studio")
        .args(["--port", "0"])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    started(child)
}

/// The studio `child` started, once it printed its address (its first line).
fn started(mut child: std::process::Child) -> Studio {
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .strip_prefix("studio: http://")
        .and_then(|s| s.strip_suffix('/'))
        .unwrap_or_else(|| panic!("first line: {line:?}"))
        .to_owned();
    Studio { child, addr }
}

/// One HTTP/1.1 exchange: (status, body).
fn http(
    addr: &str,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let has_host = headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host"));
    let mut req = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    if !has_host {
        let _ = write!(req, "Host: {addr}\r\n");
    }
    for (k, v) in headers {
        let _ = write!(req, "{k}: {v}\r\n");
    }
    let _ = write!(req, "Content-Length: {}\r\n\r\n{body}", body.len());
    s.write_all(req.as_bytes()).unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    let status = out[9..12].parse().unwrap();
    let body = out.split_once("\r\n\r\n").map_or("", |x| x.1);
    // Bodies come chunked or whole; the JSON is the part between the first '{'/'[' and
    // the last '}'/']'.
    let start = body.find(['{', '[']).unwrap_or(0);
    let end = body.rfind(['}', ']']).map_or(body.len(), |e| e + 1);
    (status, body[start..end.max(start)].to_owned())
}

fn robobus_run(request: &Value) -> Value {
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["run", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(request.to_string().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn api_run_answers_what_robobus_run_prints() {
    let s = start(&[]);
    assert!(
        s.addr.starts_with("127.0.0.1:"),
        "loopback by default: {}",
        s.addr
    );
    for request in [
        json!({"op": "wck.status", "ids": "0-2"}),
        json!({"op": "whj.status", "joints": "1-3"}),
        json!({"op": "wck.get", "param": "gains", "id": 4}),
        json!({"op": "whj.read", "joints": "2", "register": "SYS_ID"}),
        json!({"op": "wck.program.check", "program": "move 100 torque 1\ndelay 150ms\n"}),
    ] {
        let (status, body) = http(&s.addr, "POST", "/api/run", &[], &request.to_string());
        assert_eq!(status, 200, "{request}: {body}");
        let report: Value = serde_json::from_str(&body).unwrap();
        assert_eq!(report, robobus_run(&request), "{request}");
    }
    // A silent device: the same report, with its failure (200: the request ran).
    let request = json!({"op": "wck.status", "ids": "0,20"});
    let (status, body) = http(&s.addr, "POST", "/api/run", &[], &request.to_string());
    assert_eq!(status, 200);
    let report: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(report["failed"], "no-device");
    assert_eq!(report["results"][1]["id"], 20);
    // Errors as {kind, message} with the kind's status, nothing sent.
    let (status, body) = http(
        &s.addr,
        "POST",
        "/api/run",
        &[],
        r#"{"op":"wck.move","id":3,"position":300}"#,
    );
    assert_eq!(status, 400, "{body}");
    let e: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(e["kind"], "bad-input");
    assert!(e["message"].as_str().unwrap().contains("300"), "{body}");
    let (status, body) = http(&s.addr, "POST", "/api/run", &[], r#"{"op":"nope"}"#);
    assert_eq!(
        (
            status,
            serde_json::from_str::<Value>(&body).unwrap()["kind"].clone()
        ),
        (400, json!("bad-input"))
    );
    // Motion without an armed session is refused, and the servo did not move.
    let before: Value = serde_json::from_str(&http(&s.addr, "GET", "/api/sim", &[], "").1).unwrap();
    let (status, body) = http(
        &s.addr,
        "POST",
        "/api/run",
        &[],
        r#"{"op":"wck.move","id":3,"position":60}"#,
    );
    assert_eq!(status, 409, "{body}");
    let after: Value = serde_json::from_str(&http(&s.addr, "GET", "/api/sim", &[], "").1).unwrap();
    assert_eq!(before["wck"][3]["mode"], after["wck"][3]["mode"]);
    assert_eq!(after["wck"][3]["position"], 127);
    // A dry run: the plan, the same text as the CLI's --dry-run, and what it needs.
    let (status, body) = http(
        &s.addr,
        "POST",
        "/api/plan",
        &[],
        r#"{"op":"wck.set-id","id":3,"new_id":5}"#,
    );
    assert_eq!(status, 200);
    let plan: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(plan["effect"], "configure");
    assert!(plan["confirm"].is_string(), "{body}");
    assert!(plan["text"].as_str().unwrap().contains("FF"), "{body}");
    // The schemas are `robobus schema`'s.
    let (status, body) = http(&s.addr, "GET", "/api/schema", &[], "");
    assert_eq!(status, 200);
    let schema: Value = serde_json::from_str(&body).unwrap();
    let cli = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .arg("schema")
        .output()
        .unwrap();
    assert_eq!(
        schema,
        serde_json::from_slice::<Value>(&cli.stdout).unwrap()
    );
    // The session's traffic, as a capture `robobus replay` reads.
    let dir = tempfile::tempdir().unwrap();
    for bus in ["sim-wck", "sim-whj"] {
        let (status, body) = http(&s.addr, "GET", &format!("/api/capture/{bus}"), &[], "");
        assert_eq!(status, 200);
        let file = dir.path().join(format!("{bus}.log"));
        std::fs::write(&file, &body).unwrap();
        let replay = Command::new(env!("CARGO_BIN_EXE_robobus"))
            .args(["replay", "--json"])
            .arg(&file)
            .output()
            .unwrap();
        assert!(replay.status.success(), "{bus}: {replay:?}");
        let decoded: Value = serde_json::from_slice(&replay.stdout).unwrap();
        assert_eq!(decoded["summary"]["malformed"], 0, "{bus}: {decoded}");
        // The requests above are in it: servo 2's status read, joint 2's SYS_ID read.
        let text = decoded["entries"].to_string();
        let wanted = if bus == "sim-wck" {
            "status read servo 2"
        } else {
            "SYS_ID"
        };
        assert!(text.contains(wanted), "{bus}: {wanted} not in {text}");
    }
}

#[test]
fn foreign_host_origin_and_missing_token_are_refused() {
    let s = start(&[]);
    let (status, _) = http(
        &s.addr,
        "GET",
        "/api/info",
        &[("Host", "rebound.example:80")],
        "",
    );
    assert_eq!(status, 403);
    let (status, _) = http(&s.addr, "GET", "/", &[("Host", "rebound.example:80")], "");
    assert_eq!(status, 403);
    let foreign = [("Origin", "http://evil.example")];
    let (status, body) = http(
        &s.addr,
        "POST",
        "/api/run",
        &foreign,
        r#"{"op":"wck.status","ids":"0"}"#,
    );
    assert_eq!(status, 403, "{body}");
    let own = format!("http://{}", s.addr);
    let (status, _) = http(
        &s.addr,
        "POST",
        "/api/run",
        &[("Origin", &own)],
        r#"{"op":"wck.status","ids":"0"}"#,
    );
    assert_eq!(status, 200);
    // The WebSocket upgrade checks Origin too.
    let ws = |origin: &str| {
        let mut req = tungstenite::client::IntoClientRequest::into_client_request(format!(
            "ws://{}/api/ws",
            s.addr
        ))
        .unwrap();
        req.headers_mut().insert("Origin", origin.parse().unwrap());
        let stream = TcpStream::connect(&s.addr).unwrap();
        tungstenite::client(req, stream)
            .map(|_| ())
            .map_err(|e| match e {
                tungstenite::handshake::HandshakeError::Failure(tungstenite::Error::Http(r)) => {
                    r.status().as_u16()
                }
                other => panic!("{other}"),
            })
    };
    assert_eq!(ws("http://evil.example"), Err(403));
    assert_eq!(ws(&own), Ok(()));
    // At most 32 pages at once: the 33rd is refused until one closes.
    let open_page = || {
        tungstenite::client(
            format!("ws://{}/api/ws", s.addr),
            TcpStream::connect(&s.addr).unwrap(),
        )
    };
    let mut pages: Vec<_> = (0..32).map(|_| open_page().unwrap().0).collect();
    match open_page() {
        Err(tungstenite::handshake::HandshakeError::Failure(tungstenite::Error::Http(r))) => {
            assert_eq!(r.status().as_u16(), 503);
        }
        other => panic!("a 33rd page: {:?}", other.map(|_| ())),
    }
    pages.pop().unwrap().close(None).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while open_page().is_err() {
        assert!(
            Instant::now() < deadline,
            "the closed page's place never came back"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(pages);
    // No CORS headers, ever.
    let mut stream = TcpStream::connect(&s.addr).unwrap();
    write!(stream, "GET /api/info HTTP/1.1\r\nHost: {}\r\nOrigin: http://evil.example\r\nConnection: close\r\n\r\n", s.addr).unwrap();
    let mut raw = String::new();
    stream.read_to_string(&mut raw).unwrap();
    assert!(!raw.to_lowercase().contains("access-control-"), "{raw}");
    drop(s);

    // A token: every API request carries it.
    let dir = tempfile::tempdir().unwrap();
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, "0123456789abcdef-token\n").unwrap();
    let s = start(&["--token-file", token_file.to_str().unwrap()]);
    assert_eq!(http(&s.addr, "GET", "/api/info", &[], "").0, 401);
    let bearer = [("Authorization", "Bearer 0123456789abcdef-token")];
    assert_eq!(http(&s.addr, "GET", "/api/info", &bearer, "").0, 200);
    let wrong = [("Authorization", "Bearer 0123456789abcdef-tokem")];
    assert_eq!(http(&s.addr, "GET", "/api/info", &wrong, "").0, 401);
    drop(s);

    // Beyond loopback only with a token: refused before anything is opened.
    let out = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["studio", "--listen", "0.0.0.0:0"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("0.0.0.0:0") && err.contains("--token-file"),
        "{err}"
    );
}

fn send(ws: &mut tungstenite::WebSocket<TcpStream>, v: &Value) {
    ws.send(tungstenite::Message::Text(v.to_string().into()))
        .unwrap();
}

/// Reads messages until one of `type` (with `id`, if given) arrives.
fn wait_for(ws: &mut tungstenite::WebSocket<TcpStream>, kind: &str, id: Option<u64>) -> Value {
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        let m = ws.read().unwrap();
        let tungstenite::Message::Text(t) = m else {
            continue;
        };
        let v: Value = serde_json::from_str(&t).unwrap();
        assert!(
            !(v["type"] == "error" && id.is_some() && v["id"] == json!(id)),
            "{v}"
        );
        if v["type"] == kind && (id.is_none() || v["id"] == json!(id)) {
            return v;
        }
    }
    panic!("no {kind} message");
}

/// The secret of the first `control` message that says this page controls.
fn control_secret(ws: &mut tungstenite::WebSocket<TcpStream>) -> String {
    loop {
        let v = wait_for(ws, "control", None);
        if v["controller"] == true {
            let secret = v["secret"].as_str().unwrap().to_owned();
            assert_eq!(secret.len(), 64, "{v}");
            return secret;
        }
        assert!(
            v["secret"].is_null(),
            "a page without control has no secret: {v}"
        );
    }
}

/// A page's WebSocket (reads time out after 20 s instead of hanging the test).
fn page(s: &Studio) -> tungstenite::WebSocket<TcpStream> {
    let stream = TcpStream::connect(&s.addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let (mut ws, _) = tungstenite::client(format!("ws://{}/api/ws", s.addr), stream).unwrap();
    wait_for(&mut ws, "hello", None);
    ws
}

/// The simulators' own state of WHJ joint `joint`.
/// (The simulated joints' list fills at the serving loop's first observation, a moment
/// after the studio starts.)
fn sim_joint(s: &Studio, joint: usize) -> Value {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let (status, body) = http(&s.addr, "GET", "/api/sim", &[], "");
        assert_eq!(status, 200, "{body}");
        let v: Value = serde_json::from_str(&body).unwrap();
        let j = v["whj"][joint - 1].clone();
        if !j.is_null() {
            assert_eq!(j["id"], joint, "{body}");
            return j;
        }
        assert!(
            Instant::now() < deadline,
            "no simulated joint {joint}: {body}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The next error message (of run or jog `id`).
fn error_of(ws: &mut tungstenite::WebSocket<TcpStream>, id: u64) -> Value {
    loop {
        let v = wait_for(ws, "error", None);
        if v["id"] == id {
            return v;
        }
    }
}

/// Other local processes (HTTP: a session number, a guessed secret, none) and another page
/// (with the controller's secret copied) ask for `enable`, `mv` and `servo`: all refused.
/// `owner`, the controlling page, beats in between.
fn others_are_refused(
    studio: &Studio,
    owner: &mut tungstenite::WebSocket<TcpStream>,
    secret: &str,
    [enable, mv, servo]: [&String; 3],
) {
    // Another local process, over HTTP: a session number, a guessed secret, none.
    let guessed = "0".repeat(64);
    for (header, value, want) in [
        ("X-Robobus-Session", "1", 403),
        ("X-Robobus-Session", "0", 403),
        ("X-Robobus-Control", guessed.as_str(), 403),
        ("X-Robobus-Control", "1", 403),
        ("X-Other", "1", 409),
    ] {
        for body in [enable, mv, servo] {
            let (status, answer) = http(&studio.addr, "POST", "/api/run", &[(header, value)], body);
            assert_eq!(status, want, "{header}: {value} {body}: {answer}");
            send(owner, &json!({"type": "heartbeat"}));
        }
    }
    // Another page, with the controller's secret copied: refused, it is not its own.
    let mut other = page(studio);
    for (id, request) in [(1, enable), (2, mv)] {
        let request: Value = serde_json::from_str(request).unwrap();
        send(
            &mut other,
            &json!({"type": "run", "id": id, "request": request, "control": secret}),
        );
        let err = error_of(&mut other, id);
        assert_eq!(err["kind"], "refused", "{err}");
        assert!(
            err["message"]
                .as_str()
                .unwrap()
                .contains("another connection"),
            "{err}"
        );
    }
    send(
        &mut other,
        &json!({"type": "jog", "id": 3, "family": "whj", "device": 4, "target": 5, "control": secret}),
    );
    assert_eq!(error_of(&mut other, 3)["kind"], "refused");
    send(owner, &json!({"type": "heartbeat"}));
}

#[test]
fn only_the_controlling_pages_own_secret_changes_a_device() {
    // A long heartbeat allowance: the test's HTTP requests come between two beats.
    let studio = start(&["--heartbeat-timeout-ms", "1000"]);
    let mut owner = page(&studio);
    send(&mut owner, &json!({"type": "take-control"}));
    let secret = control_secret(&mut owner);
    // Arming proves control too.
    send(&mut owner, &json!({"type": "arm"}));
    let err = wait_for(&mut owner, "error", None);
    assert_eq!(err["kind"], "refused", "{err}");
    assert!(
        err["message"].as_str().unwrap().contains("control"),
        "{err}"
    );
    send(&mut owner, &json!({"type": "arm", "control": secret}));
    loop {
        if wait_for(&mut owner, "control", None)["armed"] == true {
            break;
        }
    }
    send(&mut owner, &json!({"type": "heartbeat"}));
    let before = sim_joint(&studio, 4);
    let wck_before = |st: &Studio| -> Value {
        serde_json::from_str::<Value>(&http(&st.addr, "GET", "/api/sim", &[], "").1).unwrap()["wck"]
            .clone()
    };
    let servos = wck_before(&studio);
    let enable = json!({"op": "whj.enable", "joints": "4"}).to_string();
    let mv = json!({"op": "whj.move", "joint": 4, "degrees": 15}).to_string();
    let servo = json!({"op": "wck.move", "id": 3, "position": 60}).to_string();

    others_are_refused(&studio, &mut owner, &secret, [&enable, &mv, &servo]);
    // Nothing moved: joint 4 and the wCK servos are as they were.
    let after = sim_joint(&studio, 4);
    assert_eq!(after["enabled"], before["enabled"], "{before} -> {after}");
    assert_eq!(
        after["target_position_deg"], before["target_position_deg"],
        "{after}"
    );
    assert_eq!(wck_before(&studio), servos);

    // The page itself, with its secret (as core.js sends it): obeyed.
    let proof = [("X-Robobus-Control", secret.as_str())];
    for body in [&enable, &mv] {
        // The page keeps beating while the request runs (the move waits for the joint).
        let (addr, secret, body) = (studio.addr.clone(), secret.clone(), body.clone());
        let request = std::thread::spawn(move || {
            let (status, answer) = http(
                &addr,
                "POST",
                "/api/run",
                &[("X-Robobus-Control", &secret)],
                &body,
            );
            assert_eq!(status, 200, "{body}: {answer}");
        });
        while !request.is_finished() {
            send(&mut owner, &json!({"type": "heartbeat"}));
            std::thread::sleep(Duration::from_millis(100));
        }
        request.join().unwrap();
    }
    let moved = sim_joint(&studio, 4);
    assert_eq!(moved["enabled"], true, "{moved}");
    assert!(
        (moved["target_position_deg"].as_f64().unwrap() - 15.0).abs() < 0.1,
        "{moved}"
    );

    // The page closes: its secret is stale, for HTTP and for any other page.
    owner.close(None).unwrap();
    while owner.read().is_ok() {}
    drop(owner);
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut next = page(&studio);
    loop {
        send(&mut next, &json!({"type": "take-control"}));
        let v = wait_for(&mut next, "control", None);
        if v["controller"] == true {
            assert_ne!(v["secret"].as_str().unwrap(), secret);
            break;
        }
        assert!(Instant::now() < deadline, "control never came free");
        std::thread::sleep(Duration::from_millis(50));
    }
    let torque = json!({"op": "wck.brake"}).to_string();
    let (status, answer) = http(&studio.addr, "POST", "/api/run", &proof, &torque);
    assert_eq!(status, 403, "{answer}");
    send(
        &mut next,
        &json!({"type": "run", "id": 1, "request": {"op": "wck.move", "id": 3, "position": 60}, "control": secret}),
    );
    assert_eq!(error_of(&mut next, 1)["kind"], "refused");
    assert_eq!(wck_before(&studio), servos);
}

#[test]
fn a_watcher_resubscribing_stalls_neither_the_server_nor_the_armed_page() {
    let s = start(&[]);
    let mut a = page(&s);
    send(&mut a, &json!({"type": "take-control"}));
    let secret = control_secret(&mut a);
    send(&mut a, &json!({"type": "arm", "control": secret}));
    send(&mut a, &json!({"type": "heartbeat"}));
    // The armed page beats every 100 ms on its own thread and notes any safe stop.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = std::sync::Arc::clone(&stop);
    let beating = std::thread::spawn(move || {
        a.get_mut()
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let mut armed = false;
        let mut next = Instant::now();
        let mut safe = Vec::new();
        while !flag.load(std::sync::atomic::Ordering::Relaxed) {
            if Instant::now() >= next {
                send(&mut a, &json!({"type": "heartbeat"}));
                next += Duration::from_millis(100);
            }
            match a.read() {
                Ok(tungstenite::Message::Text(t)) => {
                    let v: Value = serde_json::from_str(&t).unwrap();
                    if v["type"] == "control" {
                        armed = v["armed"] == true;
                    } else if v["type"] == "safe" {
                        safe.push(v);
                    }
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) => panic!("{e}"),
            }
        }
        (armed, safe)
    });
    // A watcher re-subscribes one stream at 1 frame a second, sampled every 5 s: each
    // time its previous forwarder is waiting for a sample or a frame.
    let mut w = page(&s);
    let mut slowest = Duration::ZERO;
    for _ in 0..8 {
        send(
            &mut w,
            &json!({"type": "subscribe", "stream": "j", "request": {"op": "whj.status", "joints": "1"}, "rate_hz": 0.2, "fps": 1}),
        );
        let asked = Instant::now();
        assert_eq!(http(&s.addr, "GET", "/api/info", &[], "").0, 200);
        slowest = slowest.max(asked.elapsed());
        std::thread::sleep(Duration::from_millis(300));
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let (armed, safe) = beating.join().unwrap();
    assert!(safe.is_empty(), "the armed page was stopped: {safe:?}");
    assert!(armed, "the armed page is no longer armed");
    // Answered while the re-subscriptions came, not after a forwarder's frame (1 s).
    assert!(
        slowest < Duration::from_millis(500),
        "/api/info took {slowest:?}"
    );
}

#[test]
fn the_eleventh_eeprom_write_in_a_minute_answers_429_with_retry_after() {
    let s = start(&[]);
    let write =
        json!({"op": "wck.set", "id": 0, "param": "gains", "p": 20, "d": 30, "confirm": true})
            .to_string();
    for n in 1..=10 {
        let (status, body) = http(&s.addr, "POST", "/api/run", &[], &write);
        assert_eq!(status, 200, "write {n}: {body}");
    }
    let mut stream = TcpStream::connect(&s.addr).unwrap();
    write!(
        stream,
        "POST /api/run HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{write}",
        s.addr,
        write.len()
    )
    .unwrap();
    let mut raw = String::new();
    stream.read_to_string(&mut raw).unwrap();
    assert!(raw.starts_with("HTTP/1.1 429 "), "{raw}");
    let retry: u64 = raw
        .lines()
        .find_map(|l| {
            l.to_lowercase()
                .strip_prefix("retry-after: ")
                .map(str::to_owned)
        })
        .unwrap_or_else(|| panic!("no Retry-After: {raw}"))
        .trim()
        .parse()
        .unwrap();
    assert!((1..=60).contains(&retry), "{raw}");
    assert!(raw.contains(r#""kind":"rate-limited""#), "{raw}");
    // A read is not counted.
    let (status, _) = http(
        &s.addr,
        "POST",
        "/api/run",
        &[],
        r#"{"op":"wck.status","ids":"0"}"#,
    );
    assert_eq!(status, 200);
}

#[test]
fn a_token_studio_on_every_address_answers_the_names_clients_use() {
    let dir = tempfile::tempdir().unwrap();
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, "0123456789abcdef-token\n").unwrap();
    let s = start(&[
        "--listen",
        "0.0.0.0:0",
        "--token-file",
        token_file.to_str().unwrap(),
    ]);
    let port = s.addr.rsplit_once(':').unwrap().1.to_owned();
    let local = format!("127.0.0.1:{port}");
    let bearer = ("Authorization", "Bearer 0123456789abcdef-token");
    for host in [local.clone(), format!("localhost:{port}")] {
        let (status, body) = http(&local, "GET", "/api/info", &[("Host", &host), bearer], "");
        assert_eq!(status, 200, "Host {host}: {body}");
        let origin = format!("http://{host}");
        let (status, body) = http(
            &local,
            "POST",
            "/api/run",
            &[("Host", &host), ("Origin", &origin), bearer],
            r#"{"op":"wck.status","ids":"0"}"#,
        );
        assert_eq!(status, 200, "Host {host}: {body}");
        // The page is served under that name too.
        assert_eq!(http(&local, "GET", "/", &[("Host", &host)], "").0, 200);
    }
    // The token is still the proof: a wrong one or none is 401.
    let wrong = ("Authorization", "Bearer 0123456789abcdef-tokem");
    assert_eq!(
        http(&local, "GET", "/api/info", &[("Host", &local), wrong], "").0,
        401
    );
    assert_eq!(
        http(&local, "GET", "/api/info", &[("Host", &local)], "").0,
        401
    );
    // Another port's name, or another site's page, is not this studio.
    let other = format!("localhost:{}", port.parse::<u16>().unwrap() ^ 1);
    assert_eq!(
        http(&local, "GET", "/api/info", &[("Host", &other), bearer], "").0,
        403
    );
    let (status, _) = http(
        &local,
        "POST",
        "/api/run",
        &[("Host", &local), ("Origin", "http://evil.example"), bearer],
        r#"{"op":"wck.status","ids":"0"}"#,
    );
    assert_eq!(status, 403);
}

/// The folders in `tmp` a studio made (`robobus-studio-*`), but `except`.
#[cfg(unix)]
fn studio_dirs(tmp: &std::path::Path, except: &std::path::Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(tmp)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p != except
                && p.file_name()
                    .unwrap()
                    .to_string_lossy()
                    .starts_with("robobus-studio-")
        })
        .collect()
}

/// Stops a studio as Ctrl-C does, and waits for it to end.
#[cfg(unix)]
fn interrupt(mut s: Studio) {
    let pid = s.child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-INT", &pid])
            .status()
            .unwrap()
            .success()
    );
    let deadline = Instant::now() + Duration::from_secs(20);
    while s.child.try_wait().unwrap().is_none() {
        assert!(
            Instant::now() < deadline,
            "the studio did not stop on SIGINT"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[cfg(unix)] // mode 0700, and symbolic links swapped in (a privilege on Windows)
#[test]
fn the_capture_folder_is_private_fresh_and_only_its_own_files_are_removed() {
    use std::os::unix::fs::PermissionsExt as _;
    let tmp = tempfile::tempdir().unwrap();
    // A folder someone made in advance with the studio's prefix, open to all, holding
    // their file: never adopted, never deleted.
    let planted = tmp.path().join("robobus-studio-planted");
    std::fs::create_dir(&planted).unwrap();
    std::fs::set_permissions(&planted, std::fs::Permissions::from_mode(0o777)).unwrap();
    std::fs::write(planted.join("theirs"), "their file").unwrap();
    let secret = tmp.path().join("secret");
    std::fs::write(&secret, "TOP-SECRET").unwrap();

    let s = start_in(&[], tmp.path());
    let pid = s.child.id().to_string();
    let dirs = studio_dirs(tmp.path(), &planted);
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    let dir = dirs[0].clone();
    let name = dir.file_name().unwrap().to_string_lossy().into_owned();
    assert!(!name.contains(&pid), "a predictable name: {name}");
    let mode = std::fs::symlink_metadata(&dir)
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o7777, 0o700, "{name}: {mode:o}");
    assert!(std::fs::read_dir(&planted).unwrap().count() == 1);
    let (status, body) = http(&s.addr, "GET", "/api/capture/sim-wck", &[], "");
    assert_eq!(status, 200, "{body}");

    // A symbolic link swapped in for a capture file is not followed.
    let files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(!files.is_empty());
    for f in &files {
        std::fs::remove_file(f).unwrap();
        std::os::unix::fs::symlink(&secret, f).unwrap();
    }
    for bus in ["sim-wck", "sim-whj"] {
        let (status, body) = http(&s.addr, "GET", &format!("/api/capture/{bus}"), &[], "");
        assert_eq!(status, 409, "{bus}: {body}");
        assert!(!body.contains("TOP-SECRET"), "{bus}: {body}");
        assert!(body.contains("not followed"), "{bus}: {body}");
    }
    // A file the studio did not make, found in its folder at the end, stays.
    std::fs::write(dir.join("not-the-studios"), "kept").unwrap();
    interrupt(s);
    assert_eq!(
        std::fs::read_to_string(planted.join("theirs")).unwrap(),
        "their file"
    );
    assert_eq!(std::fs::read_to_string(&secret).unwrap(), "TOP-SECRET");
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        left,
        ["not-the-studios"],
        "the studio's own files are removed"
    );

    // Without anything foreign, the folder is gone at the end.
    let s = start_in(&[], tmp.path());
    let mut dirs = studio_dirs(tmp.path(), &planted);
    dirs.retain(|d| *d != dir);
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    interrupt(s);
    assert!(!dirs[0].exists(), "{}", dirs[0].display());
}

#[cfg(unix)] // sh and ulimit
#[test]
fn idle_and_slow_connections_are_closed_and_never_starve_the_api() {
    // 256 file descriptors, as the report that found the flaw: more idle connections
    // than that would leave nothing for /api/info without the cap.
    let s = started(
        Command::new("sh")
            .args(["-c", "ulimit -n 256 && exec \"$0\" studio --port 0"])
            .arg(env!("CARGO_BIN_EXE_robobus"))
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap(),
    );
    // 200 connections that say nothing and 100 that send half a header, slowly.
    let opened = Instant::now();
    let mut flood = Vec::new();
    for n in 0..300 {
        let mut c = TcpStream::connect(&s.addr).unwrap();
        if n % 3 == 0 {
            write!(c, "GET /api/info HTTP/1.1\r\nHost: {}\r\nX-Slow:", s.addr).unwrap();
        }
        flood.push(c);
    }
    // The API still answers during the flood.
    for _ in 0..5 {
        let asked = Instant::now();
        let (status, body) = http(&s.addr, "GET", "/api/info", &[], "");
        assert_eq!(status, 200, "{body}");
        assert!(
            asked.elapsed() < Duration::from_secs(5),
            "{:?}",
            asked.elapsed()
        );
        for c in flood.iter_mut().step_by(3) {
            // A byte of the header now and then: still slower than the header timeout.
            let _ = c.write_all(b"a");
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    // After the header timeout, the server has closed every one of them.
    let timeout = Duration::from_secs(robobus_studio_header_timeout_s());
    std::thread::sleep(
        (opened + timeout + Duration::from_secs(2)).saturating_duration_since(Instant::now()),
    );
    let mut open = 0;
    for c in &mut flood {
        c.set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        let mut buf = [0u8; 1024];
        loop {
            match c.read(&mut buf) {
                Ok(0) => break,
                // A 503 or 408 before the close.
                Ok(_) => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    open += 1;
                    break;
                }
                Err(_) => break,
            }
        }
    }
    assert_eq!(
        open, 0,
        "of 300 idle or slow connections, {open} are still open"
    );
    assert_eq!(http(&s.addr, "GET", "/api/info", &[], "").0, 200);
}

/// The header timeout of the studio, s (docs/studio.md says it).
#[cfg(unix)]
const fn robobus_studio_header_timeout_s() -> u64 {
    10
}

/// The guard's `safe` report and the end of run `id`, which come in either order.
fn safe_and_end(ws: &mut tungstenite::WebSocket<TcpStream>, id: u64) -> (Value, Value) {
    let (mut event, mut ended) = (None, None);
    while event.is_none() || ended.is_none() {
        let v: Value = match ws.read().unwrap() {
            tungstenite::Message::Text(t) => serde_json::from_str(&t).unwrap(),
            _ => continue,
        };
        if v["type"] == "safe" {
            event = Some(v);
        } else if v["id"] == id && (v["type"] == "error" || v["type"] == "report") {
            ended = Some(v);
        }
    }
    (event.unwrap(), ended.unwrap())
}

#[test]
fn a_lost_heartbeat_brings_the_moved_joint_to_its_safe_state() {
    // A short allowance, to time the safe stop closely (the default is 500 ms).
    let s = start(&["--heartbeat-timeout-ms", "200"]);
    let stream = TcpStream::connect(&s.addr).unwrap();
    // A message that never comes fails the test instead of hanging it.
    stream
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let (mut ws, _) = tungstenite::client(format!("ws://{}/api/ws", s.addr), stream).unwrap();
    let hello = wait_for(&mut ws, "hello", None);
    assert_eq!(hello["simulated"], true);
    send(&mut ws, &json!({"type": "take-control"}));
    let secret = control_secret(&mut ws);
    // Not armed: a jog is refused and nothing moves.
    send(
        &mut ws,
        &json!({"type": "jog", "id": 1, "family": "whj", "device": 1, "target": 5, "control": secret}),
    );
    let refused = loop {
        let v: Value = match ws.read().unwrap() {
            tungstenite::Message::Text(t) => serde_json::from_str(&t).unwrap(),
            _ => continue,
        };
        if v["type"] == "error" && v["id"] == 1 {
            break v;
        }
    };
    assert_eq!(refused["kind"], "refused");
    send(&mut ws, &json!({"type": "arm", "control": secret}));
    let run = |ws: &mut tungstenite::WebSocket<TcpStream>, id: u64, request: Value| {
        send(
            ws,
            &json!({"type": "run", "id": id, "request": request, "control": secret}),
        );
        send(ws, &json!({"type": "heartbeat"}));
        wait_for(ws, "report", Some(id))
    };
    run(&mut ws, 2, json!({"op": "whj.disable", "joints": "1"}));
    run(
        &mut ws,
        3,
        json!({"op": "whj.mode", "joints": "1", "mode": "speed"}),
    );
    run(&mut ws, 4, json!({"op": "whj.enable", "joints": "1"}));
    // A long speed target, then the page stops beating (its tab froze).
    send(
        &mut ws,
        &json!({"type": "run", "id": 5, "request": {"op": "whj.speed", "joint": 1, "rpm": 3, "duration": 20}, "control": secret}),
    );
    let sim = |s: &Studio| -> Value {
        serde_json::from_str(&http(&s.addr, "GET", "/api/sim", &[], "").1).unwrap()
    };
    let mut last_beat;
    let beat_until = Instant::now() + Duration::from_secs(10);
    loop {
        send(&mut ws, &json!({"type": "heartbeat"}));
        last_beat = Instant::now();
        let j = &sim(&s)["whj"][0];
        if j["target_speed_rpm"].as_f64().unwrap() > 2.9 {
            break;
        }
        assert!(
            Instant::now() < beat_until,
            "the speed target never reached the joint: {j}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // No more heartbeats: within 300 ms of the first missed one (due 100 ms after the
    // last), the simulated joint holds: its speed target is 0.
    let safe = loop {
        let j = sim(&s)["whj"][0].clone();
        if j["target_speed_rpm"].as_f64().unwrap() == 0.0 {
            break last_beat.elapsed();
        }
        assert!(
            last_beat.elapsed() < Duration::from_secs(3),
            "never held: {j}"
        );
        std::thread::sleep(Duration::from_millis(5));
    };
    eprintln!("held {safe:?} after the last heartbeat");
    assert!(
        safe <= Duration::from_millis(400),
        "safe {safe:?} after the last heartbeat"
    );
    let (event, ended) = safe_and_end(&mut ws, 5);
    assert_eq!(event["reason"], "heartbeat lost");
    assert_eq!(
        event["devices"],
        json!([{"family": "whj", "bus": "sim-whj", "id": 1}])
    );
    assert_eq!(event["stopped_runs"], 1);
    // The stopped run ends interrupted, and the page is disarmed.
    assert_eq!(ended["kind"], "interrupted", "{ended}");
    send(
        &mut ws,
        &json!({"type": "jog", "id": 6, "family": "whj", "device": 1, "target": 5, "control": secret}),
    );
    let v = wait_for(&mut ws, "error", None);
    assert_eq!(v["id"], 6);
    assert_eq!(v["kind"], "refused");
}

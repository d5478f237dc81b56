//! robobus-ros2-router: a Zenoh router with zenoh-plugin-ros2dds linked in, for the ROS 2
//! bridge tests (the same library as zenoh-bridge-ros2dds, whose binary is not on crates.io).
//!
//! ```text
//! robobus-ros2-router [--listen ENDPOINT]... [--connect ENDPOINT]... [--namespace NS] [--domain N]
//! ```
//!
//! - `--listen` (repeatable, default `tcp/127.0.0.1:7450`): the only endpoints it listens on.
//! - `--connect` (repeatable): Zenoh endpoints it connects to.
//! - `--namespace NS`: the plugin's namespace (`bot1` or `/bot1`): it prefixes every key it
//!   routes, so the ROS topic `/joint_states` of a node without namespace is the Zenoh key
//!   `bot1/joint_states` (the same key as `/bot1/joint_states` through a router without
//!   namespace), and a Zenoh key without the prefix keeps its own name on the ROS side.
//! - `--domain N`: the ROS domain (ROS_DOMAIN_ID of the ROS nodes), default 0.
//!
//! Mode router, multicast and gossip scouting off; the plugin's DDS discovery is limited to
//! this host (`ros_automatic_discovery_range: LOCALHOST`). `ROS_DISTRO` defaults to `jazzy`
//! when it is not set (the plugin would assume `iron` and warn).
//!
//! Readiness: one line `router: ready` on stdout (flushed) once the runtime listens and the
//! plugin runs (its liveliness token is there; it creates its DDS participant right after).
//! Nothing else is written to stdout: logs (`RUST_LOG`, default `warn`) go to stderr.
//!
//! Lifetime: it runs until SIGTERM or SIGINT, then exits 0 at once. Signals
//! rather than stdin, so that a harness may start it with stdin at /dev/null and stop it
//! with `kill PID`. Exit codes: 0 stopped by a signal, 1 failed to start, 2 bad arguments.

use std::io::Write as _;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use serde_json::json;
use tokio::signal::unix::{Signal, SignalKind, signal};
use zenoh::Config;
use zenoh::internal::plugins::PluginsManager;
use zenoh::internal::runtime::{Runtime, RuntimeBuilder};

const USAGE: &str = "usage: robobus-ros2-router [--listen ENDPOINT]... [--connect ENDPOINT]... \
                     [--namespace NS] [--domain N]";
const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7450";
const DEFAULT_ROS_DISTRO: &str = "jazzy";
/// The highest ROS domain ID whose DDS ports fit in 16 bits on Linux.
const MAX_DOMAIN: u32 = 232;
/// How long the plugin may take to come up before the router gives up.
const PLUGIN_START_TIMEOUT: Duration = Duration::from_secs(20);

#[derive(Debug)]
struct Args {
    listen: Vec<String>,
    connect: Vec<String>,
    namespace: Option<String>,
    domain: u32,
}

impl Args {
    fn parse(mut args: impl Iterator<Item = String>) -> Result<Self, String> {
        let mut parsed = Args {
            listen: Vec::new(),
            connect: Vec::new(),
            namespace: None,
            domain: 0,
        };
        while let Some(arg) = args.next() {
            let mut value = |name: &str| args.next().ok_or_else(|| format!("{name} needs a value"));
            match arg.as_str() {
                "--listen" => parsed.listen.push(value("--listen")?),
                "--connect" => parsed.connect.push(value("--connect")?),
                "--namespace" => parsed.namespace = Some(namespace(&value("--namespace")?)?),
                "--domain" => {
                    let raw = value("--domain")?;
                    parsed.domain =
                        raw.parse()
                            .ok()
                            .filter(|d| *d <= MAX_DOMAIN)
                            .ok_or_else(|| {
                                format!("--domain {raw:?}: expected an integer in 0..={MAX_DOMAIN}")
                            })?;
                }
                "-h" | "--help" => return Err(String::new()),
                other => return Err(format!("unknown argument {other:?}")),
            }
        }
        if parsed.listen.is_empty() {
            parsed.listen.push(DEFAULT_LISTEN.to_string());
        }
        Ok(parsed)
    }

    fn zenoh_config(&self) -> Result<Config, String> {
        let mut plugin = json!({
            "domain": self.domain,
            "ros_automatic_discovery_range": "LOCALHOST",
        });
        if let Some(ns) = &self.namespace {
            plugin["namespace"] = json!(ns);
        }
        let mut config = Config::default();
        for (key, value) in [
            ("mode", json!("router")),
            ("listen/endpoints", json!(self.listen)),
            ("connect/endpoints", json!(self.connect)),
            ("scouting/multicast/enabled", json!(false)),
            ("scouting/gossip/enabled", json!(false)),
            ("plugins/ros2dds", plugin),
        ] {
            config
                .insert_json5(key, &value.to_string())
                .map_err(|e| format!("config {key} = {value}: {e}"))?;
        }
        Ok(config)
    }
}

/// `bot1` or `/bot1` (or `/a/b`) to `/bot1`: the characters the plugin accepts, no empty
/// segment.
fn namespace(raw: &str) -> Result<String, String> {
    let trimmed = raw.strip_prefix('/').unwrap_or(raw);
    let valid = !trimmed.is_empty()
        && trimmed.split('/').all(|segment| {
            !segment.is_empty()
                && segment
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_')
        });
    if valid {
        Ok(format!("/{trimmed}"))
    } else {
        Err(format!(
            "--namespace {raw:?}: expected segments of [A-Za-z0-9_] separated by '/'"
        ))
    }
}

/// Waits until the plugin has declared its liveliness token `@/<zid>/@ros2_lv`: it does so
/// after checking its configuration and opening its session, right before its DDS
/// participant. A plugin that rejected its configuration never declares it.
async fn wait_for_plugin(runtime: &Runtime) -> Result<(), String> {
    let session = zenoh::session::init(runtime.clone().into())
        .await
        .map_err(|e| format!("session on the runtime: {e}"))?;
    let token = format!("@/{}/@ros2_lv", runtime.zid());
    let deadline = Instant::now() + PLUGIN_START_TIMEOUT;
    while Instant::now() < deadline {
        let replies = session
            .liveliness()
            .get(&token)
            .timeout(Duration::from_millis(500))
            .await
            .map_err(|e| format!("liveliness query {token}: {e}"))?;
        while let Ok(reply) = replies.recv_async().await {
            if reply.result().is_ok() {
                return Ok(());
            }
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    Err(format!(
        "the ros2dds plugin did not start within {PLUGIN_START_TIMEOUT:?} (no token {token})"
    ))
}

/// SIGTERM and SIGINT, caught from the moment this returns.
struct Signals {
    term: Signal,
    int: Signal,
}

impl Signals {
    fn install() -> std::io::Result<Self> {
        Ok(Signals {
            term: signal(SignalKind::terminate())?,
            int: signal(SignalKind::interrupt())?,
        })
    }

    async fn recv(&mut self) -> &'static str {
        tokio::select! {
            _ = self.term.recv() => "SIGTERM",
            _ = self.int.recv() => "SIGINT",
        }
    }
}

async fn run(args: Args) -> Result<(), String> {
    let config = args.zenoh_config()?;
    let mut plugins = PluginsManager::static_plugins_only();
    plugins.declare_static_plugin::<zenoh_plugin_ros2dds::ROS2Plugin, _>("ros2dds", true);
    let mut runtime = RuntimeBuilder::new(config)
        .plugins_manager(plugins)
        .build()
        .await
        .map_err(|e| format!("building the Zenoh runtime: {e}"))?;
    runtime
        .start()
        .await
        .map_err(|e| format!("starting the Zenoh runtime: {e}"))?;
    wait_for_plugin(&runtime).await?;
    // Before the readiness line: a harness may stop the router as soon as it reads it.
    let mut signals = Signals::install().map_err(|e| format!("installing signal handlers: {e}"))?;

    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "router: ready")
        .and_then(|()| stdout.flush())
        .map_err(|e| format!("stdout: {e}"))?;
    drop(stdout);

    let signal = signals.recv().await;
    // No `runtime.close()`: zenoh-plugin-ros2dds 1.10.2 panics while its task is dropped
    // ("Undefined face context", then an abort). Like zenoh-bridge-ros2dds, exit instead:
    // Zenoh peers see the TCP connections close, DDS peers the participant's lease expire.
    eprintln!("robobus-ros2-router: {signal}, exiting");
    Ok(())
}

fn main() -> ExitCode {
    let args = match Args::parse(std::env::args().skip(1)) {
        Ok(args) => args,
        Err(msg) if msg.is_empty() => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(msg) => {
            eprintln!("robobus-ros2-router: {msg}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    if std::env::var_os("ROS_DISTRO").is_none() {
        // SAFETY: no other thread exists yet: the Tokio runtime is built below.
        unsafe { std::env::set_var("ROS_DISTRO", DEFAULT_ROS_DISTRO) };
    }
    // Logs to stderr: stdout carries only the readiness line. The plugin's own attempt to
    // install a subscriber (which would write to stdout) then finds this one and gives up.
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();

    let rt = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("robobus-ros2-router: Tokio runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let result = rt.block_on(run(args));
    match result {
        Ok(()) => std::process::exit(0),
        Err(msg) => {
            eprintln!("robobus-ros2-router: {msg}");
            std::process::exit(1)
        }
    }
}

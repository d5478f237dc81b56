//! The robobus workspace's test harness (dev-only, never published).
//!
//! Several integration tests need what a plain `cargo test` process does not have: a
//! private network namespace (UDP multicast must never reach the machine's own network),
//! or a kernel with SocketCAN (User-Mode Linux, provisioned under `target/uml`). They all
//! work the same way: an outer `#[test]` re-runs its own test binary's `#[ignore]`d inner
//! test inside the namespace or the UML guest, with an environment variable that tells
//! the inner test where it runs, and checks the exit status and a marker line the inner
//! test prints when it got to its end. [`Inner`] is that re-run.
//!
//! Each crate's integration tests are one test binary (`tests/main.rs` declares every
//! file of `tests/` as a module), so a test's name starts with its file's module
//! (`whj_udp::inner_every_operation`): [`Inner`] takes the `module_path!()` of the
//! module that holds the inner tests and re-runs only that module's tests, and
//! [`assert_every_test_file_declared`] is the test that keeps `main.rs` declaring every
//! file.
//!
//! ```no_run
//! use robobus_testkit::Inner;
//!
//! #[test]
//! fn over_udp_in_a_private_network_namespace() {
//!     Inner::exact(module_path!(), "inner_over_udp", "ROBOBUS_IN_NETNS")
//!         .in_private_netns()
//!         .expect_marker("UDP OK");
//! }
//!
//! #[test]
//! #[ignore = "run by over_udp_in_a_private_network_namespace inside unshare -n"]
//! fn inner_over_udp() {
//!     assert!(std::env::var_os("ROBOBUS_IN_NETNS").is_some());
//!     // ... the test ...
//!     println!("UDP OK");
//! }
//! ```
//!
//! A client suite runs against the simulators, or against real devices that environment
//! variables name ([`devices`]: a wCK port and its servos, a WHJ bus and its joints, and
//! whether the suite may move them).

#![allow(clippy::panic)] // a harness that cannot run its test fails that test, loudly

pub mod devices;

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::{Command, Output};

/// The workspace root.
///
/// # Panics
/// If the workspace is not where this crate was built from.
#[must_use]
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap_or_else(|e| panic!("the workspace root: {e}"))
}

/// Runs a provisioning script from `scripts/` (such as `uml/ensure-uml` or
/// `py/ensure-venv`) and returns the last line of its standard output (the path it
/// provisioned).
///
/// # Panics
/// With the script's output, if it fails or cannot start.
#[must_use]
pub fn provision(script: &str) -> String {
    let path = workspace_root().join("scripts").join(script);
    let out = Command::new(&path)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", path.display()));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{} failed ({}):\nstdout:\n{stdout}\nstderr:\n{}",
        path.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    stdout.lines().last().unwrap_or_default().trim().to_owned()
}

/// A program to run somewhere a plain test process is not: inside a private network
/// namespace, inside User-Mode Linux, or as a child with its own environment. [`Inner`]
/// is the common case of a test binary's own inner tests.
#[derive(Debug, Clone)]
pub struct Guest {
    program: OsString,
    args: Vec<OsString>,
    env: Vec<(String, OsString)>,
    timeout_s: Option<u32>,
    nice: Option<i8>,
}

impl Guest {
    /// Runs `program` (a path, or a name on `PATH`).
    #[must_use]
    pub fn new(program: impl Into<OsString>) -> Self {
        Self {
            program: program.into(),
            args: Vec::new(),
            env: Vec::new(),
            timeout_s: None,
            nice: None,
        }
    }

    /// A shell script run by `bash -c`, with `args` as `$1`, `$2`, ...
    #[must_use]
    pub fn bash(script: &str) -> Self {
        Self::new("bash").args(["-c", script, "bash"])
    }

    /// Adds an argument.
    #[must_use]
    pub fn arg(mut self, arg: impl Into<OsString>) -> Self {
        self.args.push(arg.into());
        self
    }

    /// Adds arguments.
    #[must_use]
    pub fn args<I: IntoIterator<Item = A>, A: Into<OsString>>(mut self, args: I) -> Self {
        self.args.extend(args.into_iter().map(Into::into));
        self
    }

    /// Sets (or replaces) an environment variable of the program.
    #[must_use]
    pub fn env(mut self, key: &str, value: impl Into<OsString>) -> Self {
        self.env.retain(|(k, _)| k != key);
        self.env.push((key.to_owned(), value.into()));
        self
    }

    /// The longest the run may take, seconds (default 120 in a namespace or a child,
    /// 300 in User-Mode Linux, which boots a kernel first); then it is killed and fails.
    #[must_use]
    pub const fn timeout_s(mut self, seconds: u32) -> Self {
        self.timeout_s = Some(seconds);
        self
    }

    /// Runs it at this `nice` level (a negative one needs root and is dropped without:
    /// a guest whose one host process runs a simulator and a client keeps its timing on
    /// a busy machine).
    #[must_use]
    pub const fn nice(mut self, level: i8) -> Self {
        self.nice = Some(level);
        self
    }

    /// `timeout SECONDS [nice -n LEVEL]` in front of the rest of a command.
    fn launcher(&self, default_timeout_s: u32) -> Command {
        let mut cmd = Command::new("timeout");
        cmd.arg(self.timeout_s.unwrap_or(default_timeout_s).to_string());
        if let Some(level) = self.nice {
            cmd.args(["nice", "-n", &level.to_string()]);
        }
        cmd
    }

    /// Runs it here, in a child process with its environment variables.
    ///
    /// # Panics
    /// If `timeout` cannot start.
    #[must_use]
    pub fn here(&self) -> Ran {
        let mut cmd = self.launcher(120);
        cmd.arg(&self.program).args(&self.args);
        cmd.envs(self.env.iter().map(|(k, v)| (k, v)));
        Ran::of(
            "in a child process",
            &cmd.output()
                .unwrap_or_else(|e| panic!("cannot run {}: {e}", self.program.display())),
        )
    }

    /// Runs it inside a private network namespace (`unshare -n`) with loopback up and
    /// `224.0.0.0/4` routed to it, so UDP multicast stays in it.
    ///
    /// # Panics
    /// If `timeout` or `unshare` cannot start.
    #[must_use]
    pub fn in_private_netns(&self) -> Ran {
        let script =
            "set -e; ip link set lo up; ip route add 224.0.0.0/4 dev lo; exec \"$0\" \"$@\"";
        let mut cmd = self.launcher(120);
        cmd.args(["unshare", "-n", "sh", "-c", script])
            .arg(&self.program)
            .args(&self.args);
        cmd.envs(self.env.iter().map(|(k, v)| (k, v)));
        Ran::of(
            "inside a private network namespace (unshare -n)",
            &cmd.output().unwrap_or_else(|e| {
                panic!("cannot run `unshare -n` (util-linux; needs root or user namespaces): {e}")
            }),
        )
    }

    /// Runs it inside User-Mode Linux (`scripts/uml/run-in-uml`, after
    /// `scripts/uml/ensure-uml` provisioned the kernel): a kernel with SocketCAN and
    /// `vcan0` (CAN FD MTU), can-utils on `PATH`. The environment variables go to the
    /// guest.
    ///
    /// # Panics
    /// If the kernel cannot be provisioned or the script cannot start.
    #[must_use]
    pub fn in_uml(&self) -> Ran {
        let _ = provision("uml/ensure-uml");
        let script = workspace_root().join("scripts/uml/run-in-uml");
        let mut cmd = self.launcher(300);
        cmd.arg(&script);
        for (k, v) in &self.env {
            let mut kv = OsString::from(k);
            kv.push("=");
            kv.push(v);
            cmd.arg("--env").arg(kv);
        }
        cmd.arg("--").arg(&self.program).args(&self.args);
        Ran::of(
            "inside User-Mode Linux",
            &cmd.output()
                .unwrap_or_else(|e| panic!("cannot run {}: {e}", script.display())),
        )
    }
}

/// The inner tests of the running test binary, to re-run somewhere else.
///
/// A re-run that runs no test fails (`running 0 tests`, `0 passed`), as does one whose
/// filter names no test of the module: a renamed or moved inner test is never skipped in
/// silence.
#[derive(Debug, Clone)]
pub struct Inner {
    module: String,
    filter: String,
    exact: bool,
    ignored: bool,
    guest: Guest,
}

impl Inner {
    /// The one inner test `test` of the module `module` (the `module_path!()` of the
    /// module that defines it), told where it runs by the environment variable `env`
    /// (set to `1`; [`Inner::env`] sets others).
    #[must_use]
    pub fn exact(module: &str, test: &str, env: &str) -> Self {
        Self {
            module: module.to_owned(),
            filter: test.to_owned(),
            exact: true,
            ignored: true,
            guest: Guest::new(current_exe()).env(env, "1"),
        }
    }

    /// Every inner test of the module `module` (its `module_path!()`, nested modules
    /// included) whose name in it contains `filter`; tests of other modules whose names
    /// contain it too are not run.
    #[must_use]
    pub fn matching(module: &str, filter: &str, env: &str) -> Self {
        Self {
            exact: false,
            ..Self::exact(module, filter, env)
        }
    }

    /// Sets (or replaces) the environment variable `key` for the inner tests.
    #[must_use]
    pub fn env(mut self, key: &str, value: impl Into<OsString>) -> Self {
        self.guest = self.guest.env(key, value);
        self
    }

    /// The longest the re-run may take, seconds (see [`Guest::timeout_s`]).
    #[must_use]
    pub fn timeout_s(mut self, seconds: u32) -> Self {
        self.guest = self.guest.timeout_s(seconds);
        self
    }

    /// Runs the re-run at this `nice` level (see [`Guest::nice`]).
    #[must_use]
    pub fn nice(mut self, level: i8) -> Self {
        self.guest = self.guest.nice(level);
        self
    }

    /// Runs the tests the filter names that are *not* `#[ignore]`d (by default only the
    /// ignored inner tests run): a suite re-run with other environment variables, or a
    /// test that checks where it runs itself.
    #[must_use]
    pub const fn not_ignored(mut self) -> Self {
        self.ignored = false;
        self
    }

    /// The test names to re-run, each in full (`module::test`, as the test binary names
    /// it).
    ///
    /// # Panics
    /// If the test binary cannot list its tests, or no test of the module matches.
    fn names(&self) -> Vec<String> {
        let prefix = module_prefix(&self.module);
        if self.exact {
            return vec![format!("{prefix}{}", self.filter)];
        }
        let mut list = Command::new(current_exe());
        list.args(["--list", "--format", "terse"]);
        if self.ignored {
            list.arg("--ignored");
        }
        let out = list
            .output()
            .unwrap_or_else(|e| panic!("cannot list the test binary's tests: {e}"));
        assert!(
            out.status.success(),
            "listing the test binary's tests failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        let names = select(&String::from_utf8_lossy(&out.stdout), &prefix, &self.filter);
        assert!(
            !names.is_empty(),
            "no {}test of module `{}` has `{}` in its name",
            if self.ignored { "ignored " } else { "" },
            self.module,
            self.filter
        );
        names
    }

    /// The test binary with the arguments that run the inner tests, one at a time.
    fn guest(&self) -> Guest {
        let mut args = vec!["--exact".to_owned()];
        args.extend(self.names());
        if self.ignored {
            args.push("--ignored".to_owned());
        }
        args.extend(["--nocapture", "--test-threads", "1"].map(str::to_owned));
        self.guest.clone().args(args)
    }

    /// Re-runs the inner tests here, in a child process with their environment
    /// variables (for example a client suite pointed at simulators that the calling test
    /// serves as if they were hardware).
    #[must_use]
    pub fn here(&self) -> Ran {
        self.guest().here().ran_tests()
    }

    /// Re-runs the inner tests inside a private network namespace
    /// ([`Guest::in_private_netns`]).
    #[must_use]
    pub fn in_private_netns(&self) -> Ran {
        self.guest().in_private_netns().ran_tests()
    }

    /// Re-runs the inner tests inside User-Mode Linux ([`Guest::in_uml`]).
    #[must_use]
    pub fn in_uml(&self) -> Ran {
        self.guest().in_uml().ran_tests()
    }
}

/// What a test of the module `module` (a `module_path!()`) is named by its test binary
/// before its own name: nothing in the binary's root, `a::b::` in its module `a::b`.
fn module_prefix(module: &str) -> String {
    module
        .split_once("::")
        .map_or_else(String::new, |(_crate, path)| format!("{path}::"))
}

/// The tests of a `--list --format terse` listing (`name: test` lines) named `prefix`
/// then something with `filter` in it.
fn select(listing: &str, prefix: &str, filter: &str) -> Vec<String> {
    listing
        .lines()
        .filter_map(|line| line.trim_end().strip_suffix(": test"))
        .filter(|name| {
            name.strip_prefix(prefix)
                .is_some_and(|rest| rest.contains(filter))
        })
        .map(str::to_owned)
        .collect()
}

/// How many tests a libtest run's output says passed, summed over its `test result:`
/// lines; `None` without one.
fn passed(stdout: &str) -> Option<u64> {
    let mut total = None;
    for line in stdout.lines() {
        let Some((_, result)) = line.split_once("test result: ") else {
            continue;
        };
        let count = result
            .split(';')
            .find_map(|part| part.trim().strip_suffix(" passed"))
            .and_then(|part| part.rsplit(' ').next())
            .and_then(|n| n.parse::<u64>().ok());
        if let Some(n) = count {
            total = Some(total.unwrap_or(0) + n);
        }
    }
    total
}

/// Every `*.rs` file of the `tests/` directory of the crate at `manifest_dir` (and every
/// directory there with a `main.rs` or `mod.rs`) that `main_rs` (the text of
/// `tests/main.rs`) does not declare as a module (`mod NAME;`), sorted.
///
/// # Panics
/// If the directory cannot be read.
#[must_use]
pub fn undeclared_test_files(manifest_dir: &str, main_rs: &str) -> Vec<String> {
    let declared: Vec<&str> = main_rs
        .lines()
        .filter_map(|line| {
            let line = line.trim();
            let at = line.rfind("mod ")?;
            let name = line[at + 4..].trim().strip_suffix(';')?.trim();
            let before = line[..at].trim_end();
            (before.is_empty() || before == "pub" || before.ends_with(']')).then_some(name)
        })
        .collect();
    let dir = PathBuf::from(manifest_dir).join("tests");
    let entries =
        std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()));
    let mut missing = Vec::new();
    for entry in entries {
        let path = entry
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
            .path();
        let file = path.file_name().unwrap_or_default().to_string_lossy();
        let module = if path.is_dir() {
            if !path.join("main.rs").exists() && !path.join("mod.rs").exists() {
                continue;
            }
            file.to_string()
        } else if let Some(stem) = file.strip_suffix(".rs") {
            if stem == "main" {
                continue;
            }
            stem.to_owned()
        } else {
            continue;
        };
        if !declared.contains(&module.as_str()) {
            missing.push(format!("tests/{file}"));
        }
    }
    missing.sort();
    missing
}

/// Fails naming every test file of the crate at `manifest_dir` that its `tests/main.rs`
/// (`main_rs`, its text) does not declare: `autotests = false` builds only what `main.rs`
/// declares, and a file it does not would never run.
///
/// ```no_run
/// #[test]
/// fn every_test_file_is_a_module_of_this_binary() {
///     robobus_testkit::assert_every_test_file_declared(
///         env!("CARGO_MANIFEST_DIR"),
///         include_str!("main.rs"),
///     );
/// }
/// ```
///
/// # Panics
/// Naming the files, if any is not declared.
#[track_caller]
pub fn assert_every_test_file_declared(manifest_dir: &str, main_rs: &str) {
    let missing = undeclared_test_files(manifest_dir, main_rs);
    assert!(
        missing.is_empty(),
        "tests/main.rs does not declare {} (add `mod NAME;` for each, or its tests never run)",
        missing.join(", ")
    );
}

fn current_exe() -> PathBuf {
    std::env::current_exe().unwrap_or_else(|e| panic!("the test binary: {e}"))
}

/// What a re-run printed, and how it ended.
#[derive(Debug)]
pub struct Ran {
    /// Where it ran, for messages.
    pub place: &'static str,
    /// Whether it exited 0.
    pub success: bool,
    /// Its standard output.
    pub stdout: String,
    /// Its standard error.
    pub stderr: String,
}

impl Ran {
    fn of(place: &'static str, out: &Output) -> Self {
        Self {
            place,
            success: out.status.success(),
            stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        }
    }

    /// A libtest run that ran no test is a failure: its filter named nothing.
    fn ran_tests(mut self) -> Self {
        if self.success && passed(&self.stdout).unwrap_or(0) == 0 {
            self.success = false;
            self.stderr
                .push_str("\nrobobus-testkit: the re-run ran no test (0 passed)\n");
        }
        self
    }

    /// Requires that it exited 0; returns it (its output, to look at further).
    ///
    /// # Panics
    /// With everything it printed, if not.
    #[track_caller]
    #[allow(clippy::return_self_not_must_use)] // the check is the point; the output is a bonus
    pub fn expect_success(self) -> Self {
        assert!(
            self.success,
            "the run failed {}:\nstdout:\n{}\nstderr:\n{}",
            self.place, self.stdout, self.stderr
        );
        self
    }

    /// Requires that it exited 0 and printed `marker` (the line an inner test prints
    /// when it got to its end, or `test result: ok. N passed` for several); returns its
    /// standard output.
    ///
    /// # Panics
    /// With everything it printed, if not.
    #[track_caller]
    pub fn expect_marker(self, marker: &str) -> String {
        assert!(
            self.success && self.stdout.contains(marker),
            "the inner test failed {} (no \"{marker}\"):\nstdout:\n{}\nstderr:\n{}",
            self.place,
            self.stdout,
            self.stderr
        );
        self.stdout
    }
}

#[cfg(test)]
mod tests {
    use super::{module_prefix, passed, select};

    #[test]
    fn a_module_path_becomes_the_test_name_prefix_without_the_crate() {
        assert_eq!(module_prefix("integration"), "");
        assert_eq!(module_prefix("integration::whj_udp"), "whj_udp::");
        assert_eq!(module_prefix("integration::a::b"), "a::b::");
    }

    #[test]
    fn matching_selects_only_the_modules_own_tests() {
        let listing = "whj_udp::inner_a: test\nwhj_udp::props::inner_b: test\n\
                       other::inner_c: test\nxwhj_udp::inner_d: test\nwhj_udp::outer: test\n";
        assert_eq!(
            select(listing, "whj_udp::", "inner_"),
            ["whj_udp::inner_a", "whj_udp::props::inner_b"]
        );
        assert_eq!(select(listing, "", "inner_c"), ["other::inner_c"]);
        assert!(select(listing, "nothing::", "inner_").is_empty());
    }

    #[test]
    fn zero_passed_and_no_result_line_are_told_apart_from_passes() {
        assert_eq!(
            passed(
                "running 0 tests\n\ntest result: ok. 0 passed; 0 failed; 3 filtered out; finished in 0.00s\n"
            ),
            Some(0)
        );
        assert_eq!(
            passed("test x ... ok\ntest result: ok. 4 passed; 0 failed; 0 ignored\r\n"),
            Some(4)
        );
        assert_eq!(passed("booted\nno tests here\n"), None);
    }
}

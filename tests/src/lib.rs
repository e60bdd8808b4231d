//! Helpers for tests that start real processes: locating (and building) the binaries, free
//! loopback ports, and a launcher handle that kills its process tree when dropped, so a failing
//! test leaves nothing running.

#![warn(missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// The folder holding the workspace's binaries (built once per test process).
pub fn bin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let exe = std::env::current_exe().expect("test executable path");
        // target/<profile>/deps/<test> -> target/<profile>
        let dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("target dir")
            .to_path_buf();
        let profile = dir
            .file_name()
            .and_then(|s| s.to_str())
            .unwrap_or("debug")
            .to_string();
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = Command::new(cargo);
        // `--tests` too: the same feature resolution as `cargo test` (dev-dependencies unify
        // features of shared dependencies), so the binaries are not built twice against two
        // builds of zenoh and rerun.
        cmd.args(["build", "--workspace", "--bins", "--tests", "--quiet"])
            .current_dir(workspace_root());
        // `cargo test` gives the test process its package's variables; ring's build script
        // watches CARGO_MANIFEST_DIR, so inheriting them made this build recompile ring, rustls
        // and all of rerun once per test crate (the build in scripts/test has none of them).
        for (key, _) in std::env::vars_os() {
            let Some(key) = key.to_str() else { continue };
            let per_package = key.starts_with("CARGO_PKG_")
                || key.starts_with("CARGO_MANIFEST_")
                || matches!(
                    key,
                    "CARGO_CRATE_NAME" | "CARGO_BIN_NAME" | "CARGO_PRIMARY_PACKAGE" | "CARGO_TARGET_TMPDIR"
                );
            if per_package {
                cmd.env_remove(key);
            }
        }
        if profile == "release" {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("run cargo build");
        assert!(status.success(), "cargo build --workspace --bins --tests failed");
        dir
    })
}

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// Under `CI=true` a missing tool is a failure, elsewhere a skipped check (with a message).
fn missing_tool(message: &str) {
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{message} and CI=true: run scripts/test, which installs it");
    }
    eprintln!("SKIPPED: {message}");
}

/// A Python that imports every module of `modules` (e.g. `["numpy", "mcap.reader"]`), to read
/// the project's files the way a user's own tools would: `$EVSEG_PYTHON`, else the workspace's
/// `.venv/bin/python` (made by `scripts/test`), else `/work/venv/bin/python`, else `python3`.
/// `None` when it cannot import them: the caller skips its check (`purpose` names it in the
/// message), except under `CI=true`, where that is a failure.
pub fn python_with(modules: &[&str], purpose: &str) -> Option<String> {
    let venv = workspace_root().join(".venv/bin/python");
    let exe = std::env::var("EVSEG_PYTHON").ok().unwrap_or_else(|| {
        if venv.exists() {
            venv.display().to_string()
        } else if Path::new("/work/venv/bin/python").exists() {
            "/work/venv/bin/python".to_string()
        } else {
            "python3".to_string()
        }
    });
    let imports = format!("import {}", modules.join(", "));
    let ok = Command::new(&exe)
        .args(["-c", &imports])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(exe);
    }
    missing_tool(&format!("`{imports}` fails with {exe}; {purpose} not run"));
    None
}

/// Runs `py -c script args...` (a Python from [`python_with`]) and returns what it printed on
/// standard output; panics with both of its streams when it fails.
pub fn run_python(py: &str, script: &str, args: &[&str]) -> Vec<u8> {
    let out = Command::new(py)
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "python failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// The official Rerun command-line tool, version 0.36 (`pip install rerun-sdk==0.36.*`):
/// `$EVSEG_RERUN`, else `rerun` next to `$EVSEG_PYTHON`, in the workspace's `.venv`, in
/// `/work/venv`, or on `PATH`. `None` (the check is skipped, with a message) when none runs,
/// except under `CI=true`, where that is a failure.
pub fn rerun_cli() -> Option<PathBuf> {
    let mut candidates: Vec<PathBuf> = Vec::new();
    if let Ok(p) = std::env::var("EVSEG_RERUN") {
        candidates.push(p.into());
    }
    if let Ok(py) = std::env::var("EVSEG_PYTHON")
        && let Some(dir) = Path::new(&py).parent()
    {
        candidates.push(dir.join("rerun"));
    }
    candidates.push(workspace_root().join(".venv/bin/rerun"));
    candidates.push("/work/venv/bin/rerun".into());
    candidates.push("rerun".into());
    for c in candidates {
        let ok = Command::new(&c)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success() && String::from_utf8_lossy(&o.stdout).contains("0.36"));
        if ok {
            return Some(c);
        }
    }
    missing_tool("no Rerun 0.36 CLI (pip install rerun-sdk==0.36.*); .rrd not read back with Rerun");
    None
}

/// Path of binary `name`.
pub fn bin(name: &str) -> PathBuf {
    bin_dir().join(name)
}

/// A TCP port on 127.0.0.1 that was free a moment ago.
pub fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind a loopback port");
    l.local_addr().expect("local addr").port()
}

/// A running `evseg` launcher; killed (with its nodes, through their parent-death signal) on drop.
pub struct Launcher {
    child: Option<Child>,
    /// Captured stdout file.
    pub stdout: PathBuf,
    /// Captured stderr file.
    pub stderr: PathBuf,
}

/// A finished launcher run.
#[derive(Debug)]
pub struct Finished {
    /// Exit status.
    pub status: ExitStatus,
    /// Everything printed on stdout.
    pub stdout: String,
    /// Everything printed on stderr.
    pub stderr: String,
}

impl Launcher {
    /// Starts `evseg <args>` in `cwd`, output captured into `cwd`.
    pub fn start(cwd: &Path, args: &[&str], tag: &str) -> Self {
        Self::start_with_env(cwd, args, tag, &[])
    }

    /// [`Launcher::start`] with extra environment variables (inherited by the nodes).
    pub fn start_with_env(cwd: &Path, args: &[&str], tag: &str, env: &[(&str, &str)]) -> Self {
        Self::start_wrapped(cwd, &[], args, tag, env)
    }

    /// [`Launcher::start_with_env`] through `wrapper` (a command and its arguments that end by
    /// executing `evseg <args>` in their own process, as `setpriv ... --` does, so that the
    /// child killed on drop is the launcher itself); no wrapper when it is empty.
    pub fn start_wrapped(
        cwd: &Path,
        wrapper: &[&str],
        args: &[&str],
        tag: &str,
        env: &[(&str, &str)],
    ) -> Self {
        let stdout = cwd.join(format!("{tag}.stdout"));
        let stderr = cwd.join(format!("{tag}.stderr"));
        let evseg = bin("evseg");
        let mut command = match wrapper.split_first() {
            Some((first, rest)) => {
                let mut c = Command::new(first);
                c.args(rest).arg(&evseg);
                c
            }
            None => Command::new(&evseg),
        };
        let child = command
            .args(args)
            .envs(env.iter().copied())
            .current_dir(cwd)
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(&stdout).expect("stdout file"))
            .stderr(std::fs::File::create(&stderr).expect("stderr file"))
            .spawn()
            .expect("start evseg");
        Self {
            child: Some(child),
            stdout,
            stderr,
        }
    }

    /// Process id of the launcher.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().map(Child::id).unwrap_or(0)
    }

    /// Waits for the launcher to end (at most `timeout`; then it is killed and the test fails).
    pub fn wait(mut self, timeout: Duration) -> Finished {
        let start = Instant::now();
        let mut child = self.child.take().expect("launcher running");
        let status = loop {
            if let Some(s) = child.try_wait().expect("wait launcher") {
                break s;
            }
            if start.elapsed() > timeout {
                let _ = child.kill();
                let _ = child.wait();
                panic!(
                    "launcher did not finish within {timeout:?}\nstderr:\n{}",
                    std::fs::read_to_string(&self.stderr).unwrap_or_default()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        Finished {
            status,
            stdout: std::fs::read_to_string(&self.stdout).unwrap_or_default(),
            stderr: std::fs::read_to_string(&self.stderr).unwrap_or_default(),
        }
    }

    /// Kills the launcher with SIGKILL (its nodes must follow by themselves).
    pub fn kill9(&mut self) {
        if let Some(c) = self.child.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
        self.child = None;
    }
}

impl Drop for Launcher {
    fn drop(&mut self) {
        self.kill9();
    }
}

/// Pids of live processes whose command line contains `needle` (reads /proc).
pub fn processes_with(needle: &str) -> Vec<u32> {
    let mut found = Vec::new();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return found;
    };
    for e in entries.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
            continue;
        };
        let Ok(cmd) = std::fs::read(e.path().join("cmdline")) else {
            continue;
        };
        let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
        // Zombies have an empty command line and are already gone as far as we care.
        if cmd.contains(needle) {
            found.push(pid);
        }
    }
    found
}

/// Waits until no process's command line contains `needle`; returns the leftovers on timeout.
pub fn wait_no_processes(needle: &str, timeout: Duration) -> Vec<u32> {
    let start = Instant::now();
    loop {
        let left = processes_with(needle);
        if left.is_empty() || start.elapsed() > timeout {
            return left;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Reads a JSON file written by a node.
pub fn read_json(path: &Path) -> serde_json::Value {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write file");
    p
}

/// Simulated seconds of [`sim_graph`]'s source.
pub const SIM_GRAPH_SECONDS: f64 = 0.3;
/// Slicer window of [`sim_graph`], milliseconds (10 full slices).
pub const SIM_GRAPH_WINDOW_MS: f64 = 30.0;

/// The small lock-step graph the whole-graph tests share: simulator (two-objects, seed 7,
/// [`SIM_GRAPH_SECONDS`]) -> slicer ([`SIM_GRAPH_WINDOW_MS`]) -> baseline segmenter ->
/// evaluator, window 2, instance `<name><port>`, router on loopback `port`. `extra` is appended
/// as is (more nodes, or a `record:` section).
pub fn sim_graph(name: &str, port: u16, extra: &str) -> String {
    format!(
        r#"name: {name}{port}
mode: lockstep
window: 2
zenoh:
  machines:
    local: {{ listen: ["tcp/127.0.0.1:{port}"] }}
nodes:
  - id: source
    run: evseg-source
    params: {{ kind: synthetic, scene: two-objects, seed: 7, seconds: {SIM_GRAPH_SECONDS} }}
  - id: slicer
    run: evseg-slicer
    params: {{ window_ms: {SIM_GRAPH_WINDOW_MS} }}
    inputs: {{ events: source/events, truth: source/truth }}
  - id: segmenter
    run: evseg-baseline
    inputs: {{ slices: slicer/slices }}
  - id: evaluator
    run: evseg-evaluator
    params: {{ sequence: two-objects }}
    inputs: {{ slices: slicer/slices, truth: slicer/truth, result: segmenter/tracks }}
{extra}"#
    )
}

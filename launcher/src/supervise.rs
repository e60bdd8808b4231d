//! Starting node processes and keeping watch over them.
//!
//! Every child gets `PR_SET_PDEATHSIG = SIGKILL` (so it dies with the launcher, even when the
//! launcher is killed with SIGKILL) and its own process group (so a Ctrl-C on the terminal
//! reaches the launcher only, which then stops the nodes in order). Output goes to one log file
//! per node.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// How long nodes get to stop after SIGTERM before they are killed.
pub const STOP_GRACE: Duration = Duration::from_secs(3);

/// Environment variable through which Zenoh reads the sizes of its runtime's thread pools (RON).
pub const ZENOH_RUNTIME_VAR: &str = "ZENOH_RUNTIME";

/// The thread pools of Zenoh's runtime in every node the launcher starts, when its own
/// environment has no [`ZENOH_RUNTIME_VAR`] (set it to choose others; nodes started by hand
/// on another machine keep Zenoh's defaults unless it is set there). One receive worker
/// instead of Zenoh 1.10's two: a node receives a few messages per slice, and with nine
/// processes on two cores the second worker only adds context switches. `evseg bench
/// pipeline`, 16 interleaved pairs of single runs on the 2-core AMD EPYC VM (2026-12-06):
/// 0.966 -> 1.006 M events/s in the mean (better in 12 pairs, the same in 2), CPU time of a run
/// 6.55 / 6.70 / 6.34 -> 6.48 / 6.26 / 5.83 s (user + system, three of the pairs).
pub const NODE_ZENOH_RUNTIME: &str = "(rx: (worker_threads: 1))";

/// A running (or finished) node process.
pub struct NodeProcess {
    /// Node id.
    pub id: String,
    /// Binary path.
    pub binary: PathBuf,
    /// Config file handed to it.
    pub config: PathBuf,
    /// Its log file.
    pub log: PathBuf,
    /// Where the node is declared in the graph file (`file:line:column`).
    pub origin: String,
    /// The process, while it runs.
    child: Option<Child>,
    /// How it ended.
    pub status: Option<ExitStatus>,
    /// Restarts done so far.
    pub restarts: u32,
}

/// Describes an exit status for people: `exit code 3` or `signal 9 (SIGKILL)`.
pub fn describe_status(s: &ExitStatus) -> String {
    if let Some(code) = s.code() {
        return format!("exit code {code}");
    }
    match s.signal() {
        Some(sig) => {
            let name = match sig {
                libc::SIGKILL => " (SIGKILL)",
                libc::SIGSEGV => " (SIGSEGV)",
                libc::SIGABRT => " (SIGABRT)",
                libc::SIGTERM => " (SIGTERM)",
                libc::SIGINT => " (SIGINT)",
                _ => "",
            };
            format!("signal {sig}{name}")
        }
        None => "unknown status".into(),
    }
}

impl NodeProcess {
    /// Starts `binary --config config`, output appended to `log`.
    pub fn spawn(
        id: &str,
        binary: &Path,
        config: &Path,
        log: &Path,
        origin: String,
    ) -> std::io::Result<Self> {
        let mut p = Self {
            id: id.to_string(),
            binary: binary.to_path_buf(),
            config: config.to_path_buf(),
            log: log.to_path_buf(),
            origin,
            child: None,
            status: None,
            restarts: 0,
        };
        p.start()?;
        Ok(p)
    }

    fn start(&mut self) -> std::io::Result<()> {
        let out = File::options().create(true).append(true).open(&self.log)?;
        let err = out.try_clone()?;
        let parent = std::process::id() as libc::pid_t;
        let mut cmd = Command::new(&self.binary);
        cmd.arg("--config")
            .arg(&self.config)
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err);
        if std::env::var_os(ZENOH_RUNTIME_VAR).is_none() {
            cmd.env(ZENOH_RUNTIME_VAR, NODE_ZENOH_RUNTIME);
        }
        // SAFETY: only async-signal-safe calls between fork and exec.
        unsafe {
            cmd.pre_exec(move || {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong, 0, 0, 0) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                // The launcher may have died between fork and prctl.
                if libc::getppid() != parent {
                    libc::_exit(1);
                }
                libc::setpgid(0, 0);
                Ok(())
            });
        }
        self.child = Some(cmd.spawn()?);
        self.status = None;
        Ok(())
    }

    /// Starts the node again after a failure.
    pub fn restart(&mut self) -> std::io::Result<()> {
        self.restarts += 1;
        self.start()
    }

    /// Stops the running process (SIGTERM, SIGKILL after [`STOP_GRACE`]) and starts it again,
    /// not counted in [`NodeProcess::restarts`] (which count failures against the node's
    /// restart policy): for the launcher's watchdog (`crate::watchdog`).
    pub fn respawn(&mut self) -> std::io::Result<()> {
        stop_all(std::slice::from_mut(self));
        self.start()
    }

    /// Polls the process; returns its status once it has ended.
    pub fn poll(&mut self) -> Option<ExitStatus> {
        if let Some(s) = self.status {
            return Some(s);
        }
        let child = self.child.as_mut()?;
        match child.try_wait() {
            Ok(Some(s)) => {
                self.status = Some(s);
                self.child = None;
                Some(s)
            }
            _ => None,
        }
    }

    /// Process id while running.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    fn signal(&self, sig: libc::c_int) {
        if let Some(pid) = self.pid() {
            // SAFETY: plain kill(2) on our own child.
            unsafe {
                libc::kill(pid as libc::pid_t, sig);
            }
        }
    }

    /// The last `n` lines of the node's log.
    pub fn log_tail(&self, n: usize) -> String {
        tail(&self.log, n)
    }
}

/// The last `n` lines of a text file (at most the last 64 KiB are read), with every run of
/// stack-backtrace frame lines (`  12: symbol`, `at file:line`) shortened to one line saying how
/// many were left out: a library's error logged with its backtrace while a node stops (Zenoh
/// does, e.g. when a shared-memory handoff fails) would otherwise fill the tail and hide the
/// node's own error above it.
pub fn tail(path: &Path, n: usize) -> String {
    let Ok(mut f) = File::open(path) else {
        return String::new();
    };
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let start = len.saturating_sub(64 * 1024);
    if f.seek(SeekFrom::Start(start)).is_err() {
        return String::new();
    }
    let mut buf = Vec::new();
    let _ = f.read_to_end(&mut buf);
    let text = String::from_utf8_lossy(&buf);
    let lines = without_backtraces(text.lines());
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// True for a line of a printed Rust stack backtrace: a frame (`   4: path::to::fn`) or its
/// location (`      at src/x.rs:10:5`).
fn is_backtrace_frame(line: &str) -> bool {
    let t = line.trim_start();
    if t.len() == line.len() {
        return false; // frames are indented
    }
    if t.starts_with("at ") {
        return true;
    }
    let digits = t.bytes().take_while(u8::is_ascii_digit).count();
    digits > 0 && t[digits..].starts_with(": ")
}

/// `lines` with each run of backtrace frame lines replaced by one line counting them.
fn without_backtraces<'a>(lines: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut out = Vec::new();
    let mut run = 0usize;
    for line in lines {
        if is_backtrace_frame(line) {
            run += 1;
            continue;
        }
        if run > 0 {
            out.push(format!("    ({run} backtrace lines left out)"));
            run = 0;
        }
        out.push(line.to_string());
    }
    if run > 0 {
        out.push(format!("    ({run} backtrace lines left out)"));
    }
    out
}

/// Stops every running process: SIGTERM, then SIGKILL after [`STOP_GRACE`].
pub fn stop_all(procs: &mut [NodeProcess]) {
    for p in procs.iter() {
        p.signal(libc::SIGTERM);
    }
    let start = Instant::now();
    while start.elapsed() < STOP_GRACE {
        if procs.iter_mut().all(|p| p.poll().is_some() || p.pid().is_none()) {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    for p in procs.iter_mut() {
        if p.poll().is_none() {
            p.signal(libc::SIGKILL);
            if let Some(c) = p.child.as_mut() {
                let _ = c.wait();
            }
        }
    }
}

/// Owns the node processes; kills whatever still runs when dropped (errors, panics).
pub struct Fleet(pub Vec<NodeProcess>);

impl Drop for Fleet {
    fn drop(&mut self) {
        if self.0.iter_mut().any(|p| p.poll().is_none() && p.pid().is_some()) {
            stop_all(&mut self.0);
        }
    }
}

#[cfg(test)]
mod tail_tests {
    use super::*;

    #[test]
    fn backtrace_frames_do_not_push_the_error_out_of_the_tail() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("node.log");
        let mut text = String::from("started\nERROR window must be a positive number\nstack backtrace:\n");
        for k in 0..30 {
            text += &format!("  {k:2}: zenoh_transport::thing{k}\n             at src/x.rs:{k}:5\n");
        }
        text += "closed\n";
        std::fs::write(&log, text).unwrap();
        let t = tail(&log, 5);
        assert!(t.contains("window must be a positive number"), "{t}");
        assert!(t.contains("(60 backtrace lines left out)"), "{t}");
        assert!(t.ends_with("closed"), "{t}");
        // Ordinary indented lines and numbers stay.
        assert!(!is_backtrace_frame("  value: 3"));
        assert!(!is_backtrace_frame("12: not indented"));
        assert!(is_backtrace_frame("   4: core::panicking::panic_fmt"));
        assert!(is_backtrace_frame("             at /rustc/x/panicking.rs:80:14"));
    }
}

#[cfg(test)]
mod env_tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn nodes_get_the_launchers_zenoh_runtime_or_its_default() {
        let dir = tempfile::tempdir().unwrap();
        let script = dir.path().join("print-runtime");
        std::fs::write(&script, "#!/bin/sh\necho \"runtime=[$ZENOH_RUNTIME]\"\n").unwrap();
        std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
        let (config, log) = (dir.path().join("node.yaml"), dir.path().join("node.log"));
        let mut fleet = Fleet(vec![
            NodeProcess::spawn("printer", &script, &config, &log, "test".into()).unwrap(),
        ]);
        let start = Instant::now();
        while fleet.0[0].poll().is_none() {
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "the script did not end"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        let expected = std::env::var(ZENOH_RUNTIME_VAR).unwrap_or_else(|_| NODE_ZENOH_RUNTIME.to_string());
        let printed = std::fs::read_to_string(&log).unwrap();
        assert_eq!(printed.trim(), format!("runtime=[{expected}]"));
    }
}

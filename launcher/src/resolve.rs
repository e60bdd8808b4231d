//! Finding node binaries and asking them to describe themselves.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use evseg_schemas::describe::NodeDescription;

/// Longest a binary may take to answer `--describe`.
pub const DESCRIBE_TIMEOUT: Duration = Duration::from_secs(10);

/// A located binary and its description, or why there is none.
type Resolved = Result<(PathBuf, NodeDescription), String>;

/// Finds binaries (next to the launcher, then on PATH; a name with a `/` is a path relative to
/// the graph file) and caches their descriptions.
pub struct BinaryResolver {
    graph_dir: PathBuf,
    cache: Mutex<HashMap<String, Resolved>>,
}

impl BinaryResolver {
    /// A resolver for a graph file in `graph_dir`.
    pub fn new(graph_dir: &Path) -> Self {
        Self {
            graph_dir: graph_dir.to_path_buf(),
            cache: Mutex::new(HashMap::new()),
        }
    }

    /// Where `name` is.
    pub fn locate(&self, name: &str) -> Result<PathBuf, String> {
        if name.contains('/') {
            let p = self.graph_dir.join(name);
            return if p.is_file() {
                Ok(p)
            } else {
                Err(format!("no file {}", p.display()))
            };
        }
        let mut beside = None;
        if let Ok(exe) = std::env::current_exe()
            && let Some(dir) = exe.parent()
        {
            let p = dir.join(name);
            if p.is_file() {
                return Ok(p);
            }
            beside = Some(dir.display().to_string());
        }
        if let Some(path) = std::env::var_os("PATH") {
            for dir in std::env::split_paths(&path) {
                let p = dir.join(name);
                if p.is_file() {
                    return Ok(p);
                }
            }
        }
        Err(match beside {
            Some(dir) => {
                format!("binary `{name}` not found (looked next to the launcher in {dir} and on PATH)")
            }
            None => format!("binary `{name}` not found (looked on PATH)"),
        })
    }

    /// Path and description of `name`.
    pub fn describe(&self, name: &str) -> Result<(PathBuf, NodeDescription), String> {
        if let Some(hit) = self.cache.lock().map_err(|e| e.to_string())?.get(name) {
            return hit.clone();
        }
        let result = self
            .locate(name)
            .and_then(|path| run_describe(&path, DESCRIBE_TIMEOUT).map(|d| (path, d)));
        self.cache
            .lock()
            .map_err(|e| e.to_string())?
            .insert(name.to_string(), result.clone());
        result
    }
}

/// Runs `path --describe`: its output is read while it runs (a description larger than a pipe
/// buffer cannot block it), and after `timeout` ([`DESCRIBE_TIMEOUT`]) its whole process group
/// is killed (a wrapper script's own children too: killing only the script left them running).
fn run_describe(path: &Path, timeout: Duration) -> Result<NodeDescription, String> {
    use std::os::unix::process::CommandExt;
    let spawn = || {
        Command::new(path)
            .arg("--describe")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn()
    };
    // A binary just written (a build, a test's script) can be busy for a moment: another
    // thread's child forked while it was open for writing holds it until that child execs.
    let mut tries = 0;
    let mut child = loop {
        match spawn() {
            Err(e) if e.raw_os_error() == Some(libc::ETXTBSY) && tries < 20 => {
                tries += 1;
                std::thread::sleep(Duration::from_millis(25));
            }
            other => break other.map_err(|e| format!("cannot start {}: {e}", path.display()))?,
        }
    };
    let stdout = read_in_background(child.stdout.take());
    let stderr = read_in_background(child.stderr.take());
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if start.elapsed() > timeout => {
                kill_group(&mut child);
                return Err(format!(
                    "{} --describe did not answer within {} s",
                    path.display(),
                    timeout.as_secs_f64()
                ));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(10)),
            Err(e) => {
                kill_group(&mut child);
                return Err(format!("{}: {e}", path.display()));
            }
        }
    };
    // The child has exited. A process it left behind may still hold the pipes: its group
    // (which it is then still a member of) is killed so that the readers end.
    let mut collect = |rx: std::sync::mpsc::Receiver<Vec<u8>>| {
        rx.recv_timeout(Duration::from_secs(2)).unwrap_or_else(|_| {
            kill_group(&mut child);
            rx.recv_timeout(Duration::from_secs(2)).unwrap_or_default()
        })
    };
    let out = std::process::Output {
        status,
        stdout: collect(stdout),
        stderr: collect(stderr),
    };
    if !out.status.success() {
        return Err(format!(
            "{} --describe failed ({}): {}",
            path.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("{} --describe printed no valid description: {e}", path.display()))
}

/// Reads `pipe` to its end on a thread of its own; the bytes arrive on the returned channel.
fn read_in_background<R: std::io::Read + Send + 'static>(
    pipe: Option<R>,
) -> std::sync::mpsc::Receiver<Vec<u8>> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut buf = Vec::new();
        if let Some(mut p) = pipe {
            let _ = p.read_to_end(&mut buf);
        }
        let _ = tx.send(buf);
    });
    rx
}

/// Kills `child`'s process group (it was started as its leader) and reaps it.
fn kill_group(child: &mut std::process::Child) {
    // SAFETY: kill(2) on the child's own process group.
    unsafe {
        libc::kill(-(child.id() as libc::pid_t), libc::SIGKILL);
    }
    let _ = child.kill();
    let _ = child.wait();
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn script(dir: &Path, name: &str, body: &str) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        path
    }

    /// True once the process `pid` is gone (it may take a moment to be reaped by init).
    fn gone(pid: i32) -> bool {
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            // SAFETY: kill(2) with signal 0 only checks that the process exists.
            let exists = unsafe { libc::kill(pid, 0) } == 0;
            // A killed process not reaped yet (its new parent may not reap) is a zombie.
            let zombie = std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| {
                s.rsplit(')')
                    .next()
                    .is_some_and(|r| r.trim_start().starts_with('Z'))
            });
            if !exists || zombie {
                return true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }

    fn pid_in(file: &Path) -> i32 {
        std::fs::read_to_string(file).unwrap().trim().parse().unwrap()
    }

    #[test]
    fn a_binary_that_does_not_answer_is_killed_with_the_processes_it_started() {
        let dir = tempfile::tempdir().unwrap();
        let pids = dir.path().join("pid");
        let hang = script(
            dir.path(),
            "hang",
            &format!("sleep 300 &\necho $! > {}\nsleep 300", pids.display()),
        );
        let e = run_describe(&hang, Duration::from_millis(500)).unwrap_err();
        assert!(e.contains("did not answer within 0.5 s"), "{e}");
        assert!(gone(pid_in(&pids)), "the script's child was left running");
    }

    #[test]
    fn a_child_left_holding_the_output_does_not_keep_the_launcher_waiting() {
        let dir = tempfile::tempdir().unwrap();
        let pids = dir.path().join("pid");
        let leaves = script(
            dir.path(),
            "leaves",
            &format!("sleep 300 &\necho $! > {}\necho not-json", pids.display()),
        );
        let start = Instant::now();
        let e = run_describe(&leaves, Duration::from_secs(30)).unwrap_err();
        assert!(e.contains("printed no valid description"), "{e}");
        assert!(start.elapsed() < Duration::from_secs(10), "{:?}", start.elapsed());
        assert!(gone(pid_in(&pids)));
    }

    #[test]
    fn a_description_larger_than_a_pipe_buffer_is_read() {
        let dir = tempfile::tempdir().unwrap();
        let d = evseg_runtime::describe::Describe::new("big", "a node with a long description")
            .param("x", 1.0, &"a long parameter text. ".repeat(8000))
            .build();
        let json = dir.path().join("d.json");
        std::fs::write(&json, serde_json::to_vec(&d).unwrap()).unwrap();
        assert!(std::fs::metadata(&json).unwrap().len() > 150_000);
        let big = script(dir.path(), "big", &format!("cat {}", json.display()));
        let got = run_describe(&big, Duration::from_secs(30)).unwrap();
        assert_eq!(got.binary, "big");
    }
}

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
        let mut tried = Vec::new();
        if let Ok(exe) = std::env::current_exe()
            && let Some(dir) = exe.parent()
        {
            let p = dir.join(name);
            if p.is_file() {
                return Ok(p);
            }
            tried.push(dir.display().to_string());
        }
        if let Some(path) = std::env::var_os("PATH") {
            for dir in std::env::split_paths(&path) {
                let p = dir.join(name);
                if p.is_file() {
                    return Ok(p);
                }
            }
        }
        tried.push("PATH".into());
        Err(format!(
            "binary `{name}` not found (looked next to the launcher in {} and on PATH)",
            tried.join(", ")
        ))
    }

    /// Path and description of `name`.
    pub fn describe(&self, name: &str) -> Result<(PathBuf, NodeDescription), String> {
        if let Some(hit) = self.cache.lock().map_err(|e| e.to_string())?.get(name) {
            return hit.clone();
        }
        let result = self
            .locate(name)
            .and_then(|path| run_describe(&path).map(|d| (path, d)));
        self.cache
            .lock()
            .map_err(|e| e.to_string())?
            .insert(name.to_string(), result.clone());
        result
    }
}

fn run_describe(path: &Path) -> Result<NodeDescription, String> {
    let mut child = Command::new(path)
        .arg("--describe")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", path.display()))?;
    let start = Instant::now();
    loop {
        match child.try_wait() {
            Ok(Some(_)) => break,
            Ok(None) if start.elapsed() > DESCRIBE_TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!(
                    "{} --describe did not answer within {}s",
                    path.display(),
                    DESCRIBE_TIMEOUT.as_secs()
                ));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(10)),
            Err(e) => return Err(format!("{}: {e}", path.display())),
        }
    }
    let out = child
        .wait_with_output()
        .map_err(|e| format!("{}: {e}", path.display()))?;
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

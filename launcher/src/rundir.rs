//! The run's output folder: `runs/<instance>-<UTC date-time>[-<machine>]/` with `logs/`,
//! `config/`, the graph as written, as resolved and (recording or replaying) as started, and
//! whatever the nodes write.

use std::path::{Path, PathBuf};

use anyhow::Context;

/// Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
fn civil(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// Now as `YYYYMMDD-HHMMSS` (UTC).
pub fn timestamp() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    let (y, m, d) = civil(secs.div_euclid(86_400));
    let s = secs.rem_euclid(86_400);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        s / 3600,
        s / 60 % 60,
        s % 60
    )
}

/// Creates the run folder (a fresh one under `runs/` unless `out` is given) and its sub-folders.
pub fn create(out: Option<&Path>, instance: &str, machine: Option<&str>) -> anyhow::Result<PathBuf> {
    let dir = match out {
        Some(p) => p.to_path_buf(),
        None => {
            let mut name = format!("{instance}-{}", timestamp());
            if let Some(m) = machine {
                name.push('-');
                name.push_str(m);
            }
            let base = PathBuf::from("runs").join(&name);
            let mut dir = base.clone();
            let mut k = 1;
            while dir.exists() {
                k += 1;
                dir = PathBuf::from(format!("{}-{k}", base.display()));
            }
            dir
        }
    };
    for sub in ["logs", "config"] {
        std::fs::create_dir_all(dir.join(sub))
            .with_context(|| format!("cannot create {}", dir.join(sub).display()))?;
    }
    std::path::absolute(&dir).with_context(|| format!("cannot resolve {}", dir.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates() {
        assert_eq!(civil(0), (1970, 1, 1));
        assert_eq!(civil(20_413), (2025, 11, 21));
        assert_eq!(civil(11_016), (2000, 2, 29));
    }
}

//! The report folder: `report.json`, `report.md` and PNG plots.

pub mod figures;
pub mod font;
pub mod json;
pub mod markdown;
pub mod plots;
pub mod raster;

use std::path::{Path, PathBuf};

use crate::Evaluator;

/// Failure to write the report folder.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file or folder could not be written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Serialising the figures failed.
    #[error("cannot serialise report.json: {0}")]
    Json(#[from] serde_json::Error),
    /// PNG encoding failed.
    #[error("cannot encode {path}: {source}")]
    Png {
        /// The image's path.
        path: PathBuf,
        /// The cause.
        source: png::EncodingError,
    },
}

/// Width of one frame panel in `frames.png`, pixels (half of EVIMO2's 640 px sensors).
pub const FRAME_PANEL_WIDTH: usize = 320;

fn write(path: PathBuf, bytes: &[u8]) -> Result<PathBuf, ReportError> {
    std::fs::write(&path, bytes).map_err(|source| ReportError::Io {
        path: path.clone(),
        source,
    })?;
    Ok(path)
}

fn write_png(dir: &Path, name: &str, c: &raster::Canvas) -> Result<PathBuf, ReportError> {
    let path = dir.join(name);
    let bytes = c.to_png().map_err(|source| ReportError::Png {
        path: path.clone(),
        source,
    })?;
    write(path, &bytes)
}

/// Writes the report of `ev` (after [`Evaluator::finish`]) into `dir` (created if needed), rows
/// named `sequence`. Returns the files written.
pub fn write_report(dir: &Path, ev: &Evaluator, sequence: &str) -> Result<Vec<PathBuf>, ReportError> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let summary = ev.summary(sequence);
    let reports = ev.reports();
    let mut files = Vec::new();
    let mut images = Vec::new();
    files.push(write_png(dir, "iou.png", &figures::iou_figure(reports))?);
    images.push("iou.png");
    files.push(write_png(
        dir,
        "velocity.png",
        &figures::velocity_figure(reports),
    )?);
    images.push("velocity.png");
    if let Some(c) = figures::object_motion_figure(reports) {
        files.push(write_png(dir, "object_motion.png", &c)?);
        images.push("object_motion.png");
    }
    let frames = ev.frames(ev.params().frames_in_plot);
    if !frames.is_empty() {
        files.push(write_png(
            dir,
            "frames.png",
            &plots::frames_figure(&frames, FRAME_PANEL_WIDTH),
        )?);
        images.push("frames.png");
    }
    let json = json::report_json(&summary, reports, ev.params())?;
    files.push(write(dir.join("report.json"), json.as_bytes())?);
    let md = markdown::report_markdown(&summary, &images);
    files.push(write(dir.join("report.md"), md.as_bytes())?);
    Ok(files)
}

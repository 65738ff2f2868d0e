//! What a run leaves behind in its output folder: `trajectory.csv`,
//! `summary.json`, `checkpoint.bin` (with `--checkpoint-every`), and
//! (rendering) `frames/`, `video.mp4`, `preview.png`.
//! Names, columns and fields here are a contract with other tools.

pub mod checkpoint;
pub mod progress;
pub mod summary;
pub mod trajectory;

use std::path::Path;

/// Writes a file atomically: a temporary file in the same folder, then rename,
/// so a reader never sees half a file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension(format!(
        "{}.tmp",
        path.extension().and_then(|e| e.to_str()).unwrap_or("")
    ));
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)
}

//! What a run leaves behind in its output folder: `trajectory.csv`,
//! `summary.json`, `checkpoint.bin` (with `--checkpoint-every`), and
//! (rendering) `frames/`, `video.mp4`, `preview.png`.
//! Names, columns and fields here are a contract with other tools.

pub mod capture;
pub mod checkpoint;
pub mod decimal;
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

/// FNV-1a 64 over bytes, continued from `h` (start from `FNV_OFFSET`).
pub(crate) fn fnv1a(h: &mut u64, bytes: &[u8]) {
    for &b in bytes {
        *h ^= b as u64;
        *h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
}

pub(crate) const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

//! `--capture-islands DIR`: every contact island of `--capture-min-rows`
//! rows or more that the run solves, written to DIR as one file each
//! (`IslandTask`, bincode `config::standard()` over serde), for the solver's
//! fixtures (`tests/data/islands/`) and its benchmark (`benches/islands.rs`).
//!
//! A test aid kept out of the simulation's data: the step only keeps a
//! copy of the islands it builds (`StepSettings::capture_min_rows`), and
//! the rank that built them writes them here after the step: rank 0 after
//! each world step (`run`), a worker after each group step it ran
//! (`cluster::worker_loop`). So the files, not the run, depend on where
//! each island went; names carry the rank and a count. Writing never
//! changes the run; a file that cannot be written is reported once and
//! capturing stops.

use crate::contact::solver::IslandTask;
use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

struct Capture {
    dir: PathBuf,
    min_rows: usize,
    rank: i32,
}

static CAPTURE: Mutex<Option<Capture>> = Mutex::new(None);
static WRITTEN: AtomicU64 = AtomicU64::new(0);
static ON: AtomicBool = AtomicBool::new(false);

/// Starts capturing on this process (rank `rank`) into `dir` (made if
/// missing).
pub fn start(dir: PathBuf, min_rows: usize, rank: i32) -> std::io::Result<()> {
    std::fs::create_dir_all(&dir)?;
    *CAPTURE.lock().unwrap() = Some(Capture {
        dir,
        min_rows,
        rank,
    });
    ON.store(true, Ordering::Relaxed);
    Ok(())
}

/// The smallest island (rows) to capture, if capturing: what the step is
/// asked to keep (`StepSettings::capture_min_rows`).
pub fn min_rows() -> Option<usize> {
    if !ON.load(Ordering::Relaxed) {
        return None;
    }
    CAPTURE.lock().unwrap().as_ref().map(|c| c.min_rows)
}

/// Writes the tasks of `min_rows` rows or more, in order, if capturing.
pub fn islands(tasks: &[IslandTask]) {
    if tasks.is_empty() || !ON.load(Ordering::Relaxed) {
        return;
    }
    let guard = CAPTURE.lock().unwrap();
    let Some(c) = guard.as_ref() else { return };
    for task in tasks.iter().filter(|t| t.rows() >= c.min_rows) {
        let k = WRITTEN.fetch_add(1, Ordering::Relaxed);
        let path = c
            .dir
            .join(format!("r{}_{k:06}_{}rows.bin", c.rank, task.rows()));
        let written = bincode::serde::encode_to_vec(task, bincode::config::standard())
            .map_err(|e| e.to_string())
            .and_then(|bytes| std::fs::write(&path, bytes).map_err(|e| e.to_string()));
        if let Err(e) = written {
            eprintln!(
                "rigidsim: --capture-islands: {}: {e}; capturing stops",
                path.display()
            );
            ON.store(false, Ordering::Relaxed);
            return;
        }
    }
}

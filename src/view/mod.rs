//! `rigidsim view SCENE.toml OUT_DIR [--serve PORT]`: a finished run as a
//! replay in the browser, one self-contained HTML file, `OUT_DIR/replay.html`.
//!
//! The page carries everything it shows: the convex parts rigidsim simulates,
//! triangulated (`mesh`), the objects' colours, the bodies' masses, the
//! sampled trajectory and the energies computed from it (`replay_data`,
//! binary and base64), and the viewer's JavaScript (three.js and its orbit
//! controls, bundled from `viewer/` and committed as `viewer/dist/viewer.js`).
//! Nothing is fetched when it is opened.
//!
//! It reads only the scene and the run's own output folder (`run_output`),
//! and refuses a folder that `summary.json` says was written from another
//! scene, or from another version of this one. No MPI.

pub(crate) mod http;
pub(crate) mod mesh;
pub(crate) mod page;
pub(crate) mod replay_data;
mod run_output;
mod serve;

pub use serve::serve;

use std::fmt;
use std::path::{Path, PathBuf};

/// Why no replay was written. Each displays as one line.
#[derive(Debug)]
pub enum ViewError {
    /// The scene does not load (the message `run` would give).
    Scene(rigidsim::scene::SceneError),
    /// The output folder is missing, unfinished, written from another
    /// scene, or its files are not what a run writes.
    Folder(String),
    /// The page could not be written, or not served.
    Io(String),
}

impl ViewError {
    /// 2 for bad input (as `run` and `export`), 1 for what the machine refused.
    pub fn exit_code(&self) -> u8 {
        match self {
            ViewError::Scene(_) | ViewError::Folder(_) => 2,
            ViewError::Io(_) => 1,
        }
    }
}

impl fmt::Display for ViewError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ViewError::Scene(e) => write!(f, "{e}"),
            ViewError::Folder(m) | ViewError::Io(m) => f.write_str(m),
        }
    }
}

/// File name of the page in the output folder.
pub const PAGE_NAME: &str = "replay.html";

/// Writes `out_dir/replay.html` for the run of `scene_path` in `out_dir`
/// and returns its path.
pub fn write_replay(scene_path: &Path, out_dir: &Path) -> Result<PathBuf, ViewError> {
    let scene = rigidsim::scene::load(scene_path).map_err(ViewError::Scene)?;
    let scene_bytes = std::fs::read(scene_path).map_err(|e| {
        ViewError::Folder(format!("{}: cannot read scene: {e}", scene_path.display()))
    })?;
    let run = run_output::read(out_dir, &scene, scene_path, &scene_bytes)?;
    let data = replay_data::ReplayData::new(&scene, &run);
    let html = page::html(&scene.name, &data);
    let path = out_dir.join(PAGE_NAME);
    rigidsim::output::write_atomic(&path, html.as_bytes())
        .map_err(|e| ViewError::Io(format!("cannot write {}: {e}", path.display())))?;
    Ok(path)
}

//! Reading a run's output folder for the replay: the few fields of
//! `summary.json` the page needs, after checking the folder was written from
//! the scene given, and every row of `trajectory.csv`.

use super::ViewError;
use rigidsim::output::summary::scene_digest;
use rigidsim::output::trajectory::HEADER;
use rigidsim::scene::Scene;
use serde::Deserialize;
use std::io::BufRead;
use std::path::Path;

/// What the replay takes from `summary.json` (other fields are ignored, so
/// the check reads summaries of any version that records the scene).
#[derive(Deserialize)]
struct SummaryFields {
    scene_path: Option<String>,
    scene_digest: Option<String>,
    bodies: usize,
    sim_time_s: f64,
    end_reason: String,
    #[serde(default)]
    fallen: Vec<FallRecord>,
    energy_initial_j: f64,
    energy_final_j: f64,
}

#[derive(Deserialize)]
struct FallRecord {
    body: usize,
    time: f64,
}

/// One body at one sample, as `trajectory.csv` gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    pub position: [f64; 3],
    /// [w, x, y, z], body to world.
    pub orientation: [f64; 4],
    pub velocity: [f64; 3],
    pub angular_velocity: [f64; 3],
}

/// A finished run, checked against its scene.
pub struct RunOutput {
    pub sim_time_s: f64,
    pub end_reason: String,
    /// (body, simulated time it fell at), in the order they fell.
    pub fallen: Vec<(usize, f64)>,
    pub energy_initial_j: f64,
    pub energy_final_j: f64,
    /// Sample times, increasing.
    pub times: Vec<f64>,
    /// `rows[k * bodies + i]`: body `i` at `times[k]`.
    pub rows: Vec<Row>,
}

fn folder_error(message: String) -> ViewError {
    ViewError::Folder(message)
}

/// Reads `out_dir`, refusing it unless its `summary.json` records the digest
/// of `scene_bytes` (the file `scene` was loaded from) and its trajectory
/// holds every body of `scene` at every sample.
pub fn read(
    out_dir: &Path,
    scene: &Scene,
    scene_path: &Path,
    scene_bytes: &[u8],
) -> Result<RunOutput, ViewError> {
    let dir = out_dir.display();
    if !out_dir.is_dir() {
        return Err(folder_error(format!("{dir}: no such output folder")));
    }
    let summary_path = out_dir.join("summary.json");
    let text = std::fs::read_to_string(&summary_path).map_err(|e| {
        folder_error(if e.kind() == std::io::ErrorKind::NotFound {
            format!(
                "{dir} has no summary.json: it is not the output folder of a finished run \
                 (rigidsim {} --out {dir} writes one)",
                scene_path.display()
            )
        } else {
            format!("{}: cannot read: {e}", summary_path.display())
        })
    })?;
    let summary: SummaryFields = serde_json::from_str(&text).map_err(|e| {
        folder_error(format!(
            "{}: not a rigidsim summary ({e})",
            summary_path.display()
        ))
    })?;
    let want = scene_digest(scene_bytes);
    match summary.scene_digest.as_deref() {
        None => {
            return Err(folder_error(format!(
                "{} does not record the scene it was written from (an older rigidsim wrote it); \
                 run {} again to view it",
                summary_path.display(),
                scene_path.display()
            )));
        }
        Some(found) if found != want => {
            let from = summary
                .scene_path
                .as_deref()
                .unwrap_or("an unrecorded path");
            return Err(folder_error(format!(
                "{dir} was not written from {} as it is now: it was written from {from} \
                 (scene digest {found}, this file's is {want}); give the scene it was run from, \
                 or run this one again",
                scene_path.display()
            )));
        }
        Some(_) => {}
    }
    let bodies = scene.bodies.len();
    if summary.bodies != bodies {
        return Err(folder_error(format!(
            "{}: {} bodies, but {} has {bodies}",
            summary_path.display(),
            summary.bodies,
            scene_path.display()
        )));
    }
    let mut fallen = Vec::with_capacity(summary.fallen.len());
    for f in &summary.fallen {
        if f.body >= bodies || !f.time.is_finite() {
            return Err(folder_error(format!(
                "{}: fallen body {} at t = {} is not a body of the scene",
                summary_path.display(),
                f.body,
                f.time
            )));
        }
        fallen.push((f.body, f.time));
    }
    let (times, rows) = read_trajectory(&out_dir.join("trajectory.csv"), bodies)?;
    Ok(RunOutput {
        sim_time_s: summary.sim_time_s,
        end_reason: summary.end_reason,
        fallen,
        energy_initial_j: summary.energy_initial_j,
        energy_final_j: summary.energy_final_j,
        times,
        rows,
    })
}

/// Every sample of `trajectory.csv`: each time must list bodies 0..`bodies`
/// in order, times must increase, every number must be finite.
fn read_trajectory(path: &Path, bodies: usize) -> Result<(Vec<f64>, Vec<Row>), ViewError> {
    let shown = path.display();
    if bodies == 0 {
        return Err(folder_error(format!(
            "{shown}: the scene has no bodies to replay"
        )));
    }
    let file = std::fs::File::open(path)
        .map_err(|e| folder_error(format!("{shown}: cannot read: {e}")))?;
    let mut lines = std::io::BufReader::new(file).lines();
    let bad = |line: usize, what: String| folder_error(format!("{shown} line {line}: {what}"));
    let io = |e: std::io::Error| folder_error(format!("{shown}: cannot read: {e}"));
    match lines.next().transpose().map_err(io)? {
        Some(h) if h == HEADER => {}
        _ => return Err(bad(1, format!("the header is not {HEADER}"))),
    }
    let mut times = Vec::new();
    let mut rows = Vec::new();
    for (n, line) in lines.enumerate() {
        let line_no = n + 2;
        let line = line.map_err(io)?;
        let parts: Vec<&str> = line.split(',').collect();
        if parts.len() != 15 {
            return Err(bad(
                line_no,
                format!("{} fields where a row has 15", parts.len()),
            ));
        }
        let mut fields = [0.0f64; 15];
        for (value, field) in fields.iter_mut().zip(&parts) {
            *value = field
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| bad(line_no, format!("'{field}' is not a finite number")))?;
        }
        let body_expected = rows.len() % bodies;
        if fields[1] != body_expected as f64 {
            return Err(bad(
                line_no,
                format!(
                    "body {} where body {body_expected} of {bodies} was due: \
                     not a trajectory of this scene",
                    fields[1]
                ),
            ));
        }
        let time = fields[0];
        if body_expected == 0 {
            if times.last().is_some_and(|&t| time <= t) {
                return Err(bad(line_no, format!("time {time} does not increase")));
            }
            times.push(time);
        } else if time != *times.last().expect("a sample's first row came before") {
            return Err(bad(
                line_no,
                format!("time {time} within another sample's rows"),
            ));
        }
        let f = |i: usize| [fields[i], fields[i + 1], fields[i + 2]];
        rows.push(Row {
            position: f(2),
            orientation: [fields[5], fields[6], fields[7], fields[8]],
            velocity: f(9),
            angular_velocity: f(12),
        });
    }
    if rows.is_empty() {
        return Err(folder_error(format!("{shown}: no rows")));
    }
    if rows.len() % bodies != 0 {
        return Err(folder_error(format!(
            "{shown}: the last sample lists {} of the scene's {bodies} bodies (cut short?)",
            rows.len() % bodies
        )));
    }
    Ok((times, rows))
}

//! Inputs are data: each takes effect at a step boundary, and `inputs.jsonl`
//! keeps it with that step, one JSON object a line,
//! `{"step":S,"hand":H,"type":...}` (the message's own fields follow; a
//! grab also keeps `"local"`, the point it holds in the body's frame), and
//! a last line `{"step":N,"type":"end","end_reason":...}` with the live
//! run's last step. `rigidsim run SCENE --inputs FILE` applies them at the same
//! steps, through the same `Hands`, so a live run replays to its state hash.
//!
//! A hand's force and a push reach the step as external forces over the
//! next step (`rigidsim::scene::ForceWindow`, what `[[forces]]` gives), shared
//! with every rank that steps groups (`Executor::share_forces`); a reset
//! puts every body back to the scene's start state.

use super::hand::{self, Held};
use super::protocol::{Input, SceneFacts};
use nalgebra::Vector3;
use rigidsim::body::{Activity, BodyId};
use rigidsim::scene::{ForceWindow, Scene};
use rigidsim::step::{Executor, World};
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

/// The file name in the output folder.
pub const FILE_NAME: &str = "inputs.jsonl";

/// One input with the step boundary it took effect at (`WorldState::steps` then)
/// and the hand (connection) that sent it.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    pub step: u64,
    pub hand: u32,
    pub input: Input,
    /// For a grab: the point held, in the body's frame from its centre of
    /// mass, as the grab found it. A run resumed past the grab holds the
    /// body there without the body's state at the grab.
    pub local: Option<[f64; 3]>,
}

impl Record {
    /// Its line of `inputs.jsonl` (without the newline).
    pub fn line(&self) -> String {
        let message = serde_json::to_string(&self.input).expect("an input serialises");
        // The message is an object `{"type":...}`: step and hand go first.
        let mut line = format!(
            "{{\"step\":{},\"hand\":{},{}",
            self.step,
            self.hand,
            &message[1..]
        );
        if let Some(local) = self.local {
            line.pop();
            line += &format!(",\"local\":{}}}", serde_json::json!(local));
        }
        line
    }
}

/// The last line of `inputs.jsonl`.
pub fn end_line(step: u64, end_reason: &str) -> String {
    serde_json::json!({ "step": step, "type": "end", "end_reason": end_reason }).to_string()
}

/// A recorded live run: its inputs in the order applied, and its last step
/// (where its `end` line says it ended, or the last input's step).
#[derive(Debug)]
pub struct Recording {
    pub records: Vec<Record>,
    pub last_step: u64,
}

/// Reads an `inputs.jsonl`, checking each input against the scene as the
/// live run did (but for where bodies are, which only the run knows).
pub fn read(path: &Path, scene: &Scene) -> Result<Recording, String> {
    let file =
        std::fs::File::open(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    let facts = SceneFacts::new(scene);
    let mut records: Vec<Record> = Vec::new();
    let mut end = None;
    for (n, line) in std::io::BufReader::new(file).lines().enumerate() {
        let at = |msg: String| format!("{} line {}: {msg}", path.display(), n + 1);
        let line = line.map_err(|e| at(e.to_string()))?;
        if line.trim().is_empty() {
            continue;
        }
        if end.is_some() {
            return Err(at("a line after the \"end\" line".into()));
        }
        let mut value: serde_json::Value =
            serde_json::from_str(&line).map_err(|e| at(format!("not JSON: {e}")))?;
        let object = value
            .as_object_mut()
            .ok_or_else(|| at("not a JSON object".into()))?;
        let step = object
            .remove("step")
            .and_then(|s| s.as_u64())
            .ok_or_else(|| at("no \"step\" (a whole number)".into()))?;
        if records.last().is_some_and(|r| r.step > step) {
            return Err(at(format!("step {step} comes before the line above's")));
        }
        if object.get("type").and_then(|t| t.as_str()) == Some("end") {
            end = Some(step);
            continue;
        }
        let local = match object.remove("local") {
            None => None,
            Some(l) => Some(
                serde_json::from_value::<[f64; 3]>(l).map_err(|e| at(format!("\"local\": {e}")))?,
            ),
        };
        let hand = match object.remove("hand") {
            None => 0,
            Some(h) => h
                .as_u64()
                .and_then(|h| u32::try_from(h).ok())
                .ok_or_else(|| at("\"hand\" is not a whole number".into()))?,
        };
        let input: Input = serde_json::from_value(value).map_err(|e| at(e.to_string()))?;
        input.check(&facts, false).map_err(at)?;
        records.push(Record {
            step,
            hand,
            input,
            local,
        });
    }
    let last_step = end
        .or(records.last().map(|r| r.step))
        .ok_or_else(|| format!("{}: no inputs and no \"end\" line", path.display()))?;
    Ok(Recording { records, last_step })
}

/// Where a hand holds a body: a point fixed to it (body frame, from the
/// centre of mass), pulled towards `target`.
#[derive(Clone, Debug)]
struct Grab {
    body: u32,
    local: Vector3<f64>,
    target: Vector3<f64>,
}

/// The hands of a live run and the pushes due at the next step; turns them
/// into the step's external forces.
pub struct Hands {
    /// The scene's own `[[forces]]`.
    own: Vec<ForceWindow>,
    /// By hand, so that forces are listed in the same order every time.
    grabs: BTreeMap<u32, Grab>,
    /// (body, point, impulse) for the next step.
    pushes: Vec<(u32, Vector3<f64>, Vector3<f64>)>,
    /// The forces the other ranks hold (`Executor::share_forces`).
    shared: Vec<ForceWindow>,
}

impl Hands {
    pub fn new(scene: &Scene) -> Hands {
        Hands {
            own: scene.forces.clone(),
            grabs: BTreeMap::new(),
            pushes: Vec::new(),
            shared: scene.forces.clone(),
        }
    }

    /// Applies `input` from `hand` at this step boundary; for a grab,
    /// returns the point held in the body's frame (`Record::local`). Pause,
    /// resume and stop belong to the live run, not the world: nothing here.
    pub fn apply(&mut self, world: &mut World, hand: u32, input: &Input) -> Option<[f64; 3]> {
        match input {
            Input::Grab { body, point } => {
                let s = &world.state.bodies[*body as usize].state;
                let point = Vector3::from(*point);
                let local = s.orientation.inverse() * (point - s.position);
                self.grabs.insert(
                    hand,
                    Grab {
                        body: *body,
                        local,
                        target: point,
                    },
                );
                return Some(local.into());
            }
            Input::Drag { target } => {
                if let Some(g) = self.grabs.get_mut(&hand) {
                    g.target = Vector3::from(*target);
                }
            }
            Input::Release => {
                self.grabs.remove(&hand);
            }
            Input::Push {
                body,
                point,
                impulse,
            } => self
                .pushes
                .push((*body, Vector3::from(*point), Vector3::from(*impulse))),
            Input::Reset => {
                reset(world);
                self.grabs.clear();
                self.pushes.clear();
            }
            Input::Pause | Input::Resume | Input::Stop => {}
        }
        None
    }

    /// Takes up the hands as `record`, applied at an earlier step, left
    /// them (a run resumed from a checkpoint, which does not keep them).
    /// Pushes acted over their own step and leave nothing. False for a grab
    /// without its `local` point (written by hand): it cannot be held.
    pub fn restore(&mut self, record: &Record) -> bool {
        match (&record.input, record.local) {
            (Input::Grab { .. }, None) => return false,
            (Input::Grab { body, point }, Some(local)) => {
                self.grabs.insert(
                    record.hand,
                    Grab {
                        body: *body,
                        local: local.into(),
                        target: Vector3::from(*point),
                    },
                );
            }
            (Input::Drag { target }, _) => {
                if let Some(g) = self.grabs.get_mut(&record.hand) {
                    g.target = Vector3::from(*target);
                }
            }
            (Input::Release, _) => {
                self.grabs.remove(&record.hand);
            }
            (Input::Reset, _) => self.grabs.clear(),
            (Input::Push { .. } | Input::Pause | Input::Resume | Input::Stop, _) => {}
        }
        true
    }

    /// Sets the external forces of the next step: the scene's own, each
    /// hand's spring on the body it holds, and each push as J / dt over the
    /// step; shares them with the ranks when they changed. `after_step`
    /// takes them out again.
    pub fn forces_for_next_step(&mut self, world: &mut World, exec: &mut dyn Executor) {
        let dt = world.scene.settings.dt;
        // The step's own interval, its ends as `World::time` gives them:
        // a window left with the workers never acts in a later step.
        let start = world.time();
        let end = (world.state.steps + 1) as f64 * dt;
        let mut forces = self.own.clone();
        let window = |body: u32, force, torque| ForceWindow {
            body: BodyId(body),
            force,
            torque,
            start,
            end,
        };
        for g in self.grabs.values() {
            let b = &world.state.bodies[g.body as usize];
            if !b.is_dynamic() || b.activity == Activity::Fallen {
                continue;
            }
            let o = world.object(g.body as usize);
            let held = Held {
                mass: o.mass,
                centre: b.state.position,
                orientation: b.state.orientation,
                velocity: b.state.velocity,
                angular_velocity: b.angular_velocity(o),
            };
            let (f, tau) = hand::spring_force(&held, &g.local, &g.target, dt);
            forces.push(window(g.body, f, tau));
        }
        for (body, point, impulse) in self.pushes.drain(..) {
            let b = &world.state.bodies[body as usize];
            if b.activity == Activity::Fallen {
                continue;
            }
            let f = impulse / dt;
            forces.push(window(body, f, (point - b.state.position).cross(&f)));
        }
        if forces != self.shared {
            exec.share_forces(&forces);
            self.shared = forces.clone();
        }
        world.scene.forces = forces;
    }

    /// After the step: the scene's forces are its own again, so that a
    /// checkpoint knows the scene it was loaded from (its fingerprint
    /// counts the forces).
    pub fn after_step(&self, world: &mut World) {
        if world.scene.forces != self.own {
            world.scene.forces = self.own.clone();
        }
    }
}

/// Every body back to the scene's start state, at the current step: a new
/// world from the scene (no contacts, caches or resting systems carried
/// over), with the run's step count, settings, counters and timings.
pub fn reset(world: &mut World) {
    let mut fresh = World::new(world.scene.clone());
    fresh.state.steps = world.state.steps;
    fresh.settings = world.settings;
    fresh.diagnostics.stage = std::mem::take(&mut world.diagnostics.stage);
    fresh.diagnostics.counters = std::mem::take(&mut world.diagnostics.counters);
    fresh.diagnostics.max_penetration = world.diagnostics.max_penetration;
    fresh.state.fallen = std::mem::take(&mut world.state.fallen);
    *world = fresh;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_reads_back_as_written() {
        let scene = rigidsim::scene::load(Path::new("scenes/render_check.toml")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE_NAME);
        let records = vec![
            Record {
                step: 3,
                hand: 1,
                input: Input::Grab {
                    body: 1,
                    point: [0.1, -0.2, 0.45],
                },
                local: Some([0.1, -0.2, 1.0 / 3.0]),
            },
            Record {
                step: 3,
                hand: 1,
                input: Input::Drag {
                    target: [0.1 + 1e-17, 1.0 / 3.0, 0.7],
                },
                local: None,
            },
            Record {
                step: 9,
                hand: 2,
                input: Input::Reset,
                local: None,
            },
        ];
        let mut text: String = records.iter().map(|r| r.line() + "\n").collect();
        assert!(
            text.starts_with("{\"step\":3,\"hand\":1,\"type\":\"grab\""),
            "{text}"
        );
        text += &end_line(12, "stopped");
        std::fs::write(&path, text).unwrap();
        let back = read(&path, &scene).unwrap();
        assert_eq!(back.records, records);
        assert_eq!(back.last_step, 12);
    }
}

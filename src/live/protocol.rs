//! Every message of the live run's WebSocket, `ws://ADDR:PORT/ws`
//! (`docs/live.md` is the reference for clients). JSON text messages, one
//! object each, told apart by `"type"`.
//!
//! Server → client: `scene` once on connect (what a client needs to draw the
//! bodies), `state` after the steps (at most `MAX_STATES_PER_SECOND` a second
//! of wall time), `error` in answer to a message refused, `end` when the
//! live run ends. Client → server: `grab`, `drag`, `release`, `push`,
//! `pause`, `resume`, `reset`, `stop`: inputs, each taking effect at the
//! next step boundary and written with its step to `inputs.jsonl`.

use crate::view::replay_data::kind_name;
use nalgebra::Vector3;
use rigidsim::scene::Scene;
use rigidsim::scene::bounds;
use serde::{Deserialize, Serialize};

/// States sent at most this often per second of wall time: a display's
/// refresh; more would only queue in the socket.
pub const MAX_STATES_PER_SECOND: f64 = 60.0;

/// A client message longer than this (bytes) is refused with an error: the
/// longest valid one (a push with three 24-digit vectors) is under 200.
pub const MAX_MESSAGE_BYTES: usize = 4096;

/// Messages a connection may send per second, on average over a second (a
/// mouse reports at up to a few hundred hertz); the others are refused.
pub const MAX_MESSAGES_PER_SECOND: f64 = 250.0;

/// How far from a body's centre a hand may hold it, in multiples of the
/// body's reach (its farthest vertex from the centre of mass): the point
/// need not be on the surface, but a lever a hundred times its size would
/// spin it with the hand's whole force.
pub const GRAB_REACH: f64 = 10.0;

/// A client's message, as it arrives (`deny_unknown_fields`: a misspelt
/// field is an error, not a silent default).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Input {
    /// The hand takes `body` at `point` (world coordinates): a point fixed
    /// to the body from then on.
    Grab {
        body: u32,
        point: [f64; 3],
    },
    /// Where the hand is now (world coordinates): the grab point is pulled
    /// towards it (`hand::spring_force`).
    Drag {
        target: [f64; 3],
    },
    /// The hand lets go.
    Release,
    /// An impulse (N·s) at `point` (world coordinates) on `body`, over the
    /// next step.
    Push {
        body: u32,
        point: [f64; 3],
        impulse: [f64; 3],
    },
    /// Simulated time stops (and is not counted against the wall clock).
    Pause,
    Resume,
    /// Every body back to the scene's start state; simulated time goes on.
    /// Every hand lets go.
    Reset,
    /// Ends the live run (`end_reason = "stopped"`).
    Stop,
}

impl Input {
    /// Parses and checks a client's text against the scene: a one-line
    /// reason for the error reply when it is refused.
    pub fn parse(text: &str, scene: &SceneFacts) -> Result<Input, String> {
        if text.len() > MAX_MESSAGE_BYTES {
            return Err(format!(
                "message of {} bytes; at most {MAX_MESSAGE_BYTES}",
                text.len()
            ));
        }
        let input: Input = serde_json::from_str(text).map_err(|e| {
            format!(
                "not a message of this protocol ({e}); see docs/live.md, e.g. {{\"type\":\"pause\"}}"
            )
        })?;
        input.check(scene, true)?;
        Ok(input)
    }

    /// The scene loader's bounds, applied to an input: a body that exists
    /// and moves, points within the world's coordinates, an impulse whose
    /// push over one step accelerates no more than a scene's force may;
    /// with `near`, points within `GRAB_REACH` of the body where `scene`
    /// says it is.
    pub fn check(&self, scene: &SceneFacts, near: bool) -> Result<(), String> {
        let fail = |(field, msg): (String, String)| format!("{field}: {msg}");
        match self {
            Input::Grab { body, point } => {
                let b = scene.movable(*body)?;
                bounds::check_position(point, "point").map_err(fail)?;
                let lever = (Vector3::from(*point) - b.centre).norm();
                if near && lever > GRAB_REACH * b.reach {
                    return Err(format!(
                        "point: {lever:.3} m from body {body}'s centre; a hand holds a body \
                         within {GRAB_REACH} times its size ({:.3} m)",
                        GRAB_REACH * b.reach
                    ));
                }
            }
            Input::Drag { target } => bounds::check_position(target, "target").map_err(fail)?,
            Input::Push {
                body,
                point,
                impulse,
            } => {
                let b = scene.movable(*body)?;
                bounds::check_position(point, "point").map_err(fail)?;
                let lever = (Vector3::from(*point) - b.centre).norm();
                if near && lever > GRAB_REACH * b.reach {
                    return Err(format!(
                        "point: {lever:.3} m from body {body}'s centre; a push lands within \
                         {GRAB_REACH} times its size ({:.3} m)",
                        GRAB_REACH * b.reach
                    ));
                }
                // Over one step the impulse is a force J / dt (`inputs`).
                let force = bounds::magnitude(impulse) / scene.dt;
                bounds::check_acceleration(
                    force / b.mass,
                    "impulse",
                    &format!("over one step accelerates body {body} ({} kg) at", b.mass),
                )
                .map_err(fail)?;
                bounds::check_acceleration(
                    force * lever / b.smallest_moment * b.reach,
                    "impulse",
                    &format!("over one step accelerates body {body}'s surface at"),
                )
                .map_err(fail)?;
            }
            Input::Release | Input::Pause | Input::Resume | Input::Reset | Input::Stop => {}
        }
        Ok(())
    }
}

/// What the checks of inputs need to know of the scene and of where its
/// bodies are (rank 0's server keeps the latest, the replay reads the world).
#[derive(Clone, Debug)]
pub struct SceneFacts {
    pub dt: f64,
    pub bodies: Vec<BodyFacts>,
}

#[derive(Clone, Debug)]
pub struct BodyFacts {
    /// Only dynamic bodies can be held or pushed.
    pub kind: &'static str,
    pub mass: f64,
    pub smallest_moment: f64,
    /// Farthest vertex from the centre of mass, metres.
    pub reach: f64,
    /// Centre of mass now (world), metres.
    pub centre: Vector3<f64>,
}

impl SceneFacts {
    pub fn new(scene: &Scene) -> SceneFacts {
        SceneFacts {
            dt: scene.settings.dt,
            bodies: scene
                .bodies
                .iter()
                .map(|b| {
                    let o = &scene.objects[b.object.0 as usize];
                    BodyFacts {
                        kind: kind_name(&b.kind),
                        mass: o.mass,
                        smallest_moment: o.principal_moments.min(),
                        reach: bounds::reach(o),
                        centre: b.state.position,
                    }
                })
                .collect(),
        }
    }

    fn movable(&self, body: u32) -> Result<&BodyFacts, String> {
        let b = self.bodies.get(body as usize).ok_or_else(|| {
            format!(
                "body: no body {body} (the scene has {} bodies, numbered from 0)",
                self.bodies.len()
            )
        })?;
        if b.kind != "dynamic" {
            return Err(format!(
                "body: body {body} is {}; only dynamic bodies can be held or pushed",
                b.kind
            ));
        }
        Ok(b)
    }
}

/// `{"type":"error","message":...}`.
pub fn error_message(message: &str) -> String {
    serde_json::json!({ "type": "error", "message": message }).to_string()
}

/// `{"type":"end","end_reason":...}`: the last message of a live run.
pub fn end_message(end_reason: &str) -> String {
    serde_json::json!({ "type": "end", "end_reason": end_reason }).to_string()
}

/// `{"type":"state", ...}`: the bodies in `trajectory.csv`'s order, each
/// `[x, y, z, qw, qx, qy, qz]` (centre of mass, orientation) as f32 (far
/// below a pixel; half the text of f64).
#[derive(Serialize)]
pub struct State<'a> {
    #[serde(rename = "type")]
    pub kind: &'static str,
    /// Simulated seconds, and the steps taken.
    pub t: f64,
    pub step: u64,
    pub bodies: &'a [[f32; 7]],
    /// Indices of the bodies at rest and of those that fell below `fall_z`.
    pub resting: Vec<u32>,
    pub fallen: Vec<u32>,
    pub paused: bool,
    /// Simulated over wall seconds, over the last second or so.
    pub realtime_factor: f64,
    /// The longest wall time one frame interval of steps took, over the
    /// last few seconds; above `frame_interval_s` the live run runs behind.
    pub worst_frame_s: f64,
    pub frame_interval_s: f64,
    /// How far simulated time trails the wall clock (0 when on time).
    pub behind_s: f64,
    /// Inputs taken so far (from every client): a client that counts its
    /// own knows from which state on they have acted.
    pub inputs: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn facts() -> SceneFacts {
        let scene = rigidsim::scene::load(std::path::Path::new("scenes/render_check.toml"))
            .expect("bundled scene loads");
        SceneFacts::new(&scene)
    }

    #[test]
    fn each_message_of_the_protocol_parses() {
        let f = facts();
        let c = f.bodies[1].centre;
        let at = format!("[{},{},{}]", c.x, c.y, c.z);
        for text in [
            format!(r#"{{"type":"grab","body":1,"point":{at}}}"#),
            r#"{"type":"drag","target":[0,0,0.5]}"#.into(),
            r#"{"type":"release"}"#.into(),
            format!(r#"{{"type":"push","body":1,"point":{at},"impulse":[0,0,0.5]}}"#),
            r#"{"type":"pause"}"#.into(),
            r#"{"type":"resume"}"#.into(),
            r#"{"type":"reset"}"#.into(),
            r#"{"type":"stop"}"#.into(),
        ] {
            Input::parse(&text, &f).unwrap_or_else(|e| panic!("{text}: {e}"));
        }
    }

    #[test]
    fn bad_messages_are_refused_with_a_reason() {
        let f = facts();
        let big = format!(r#"{{"type":"pause","pad":"{}"}}"#, "x".repeat(5000));
        for (text, says) in [
            ("not json", "not a message"),
            (r#"{"type":"fly"}"#, "not a message"),
            (r#"{"type":"grab","body":7,"point":[0,0,0]}"#, "no body 7"),
            (r#"{"type":"grab","body":0,"point":[0,0,0]}"#, "is fixed"),
            (r#"{"type":"drag","target":[NaN,0,0]}"#, "not a message"),
            (r#"{"type":"drag","target":[1e300,0,0]}"#, "target"),
            (r#"{"type":"drag","target":[0,0]}"#, "not a message"),
            (r#"{"type":"grab","body":1,"point":[50,0,0]}"#, "within"),
            (
                r#"{"type":"push","body":1,"point":[0,0,0.05],"impulse":[0,0,1e12]}"#,
                "bound",
            ),
            (big.as_str(), "at most 4096"),
        ] {
            let e = Input::parse(text, &f).expect_err(text);
            assert!(e.contains(says), "{text}: {e}");
        }
    }
}

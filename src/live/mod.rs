//! `rigidsim live SCENE.toml [--port P] [--bind ADDR] [run options]`: the
//! scene stepped at the pace of the wall clock, seen in a browser as it
//! runs, and pushed by a person's hand (SPEC 2.1, step 2: user input as
//! external forces). `docs/live.md` is the reference.
//!
//! - `protocol`: every WebSocket message, and the checks of inputs;
//! - `server`: HTTP and WebSocket (axum), the page, tokens and origins;
//! - `driver`: the run loop's `Driver` on rank 0: pacing, inputs at step
//!   boundaries, states out;
//! - `pacing`: the wall clock; `hand`: the hand's spring-damper;
//! - `inputs`: `inputs.jsonl`, and inputs as the step's external forces;
//! - `replay`: `rigidsim run --inputs`, a recorded live run again;
//! - `page`: the live page (the replay viewer's scene, camera and picking).
//!
//! The step knows nothing of any of it: inputs reach it as external forces
//! (`rigidsim::scene::ForceWindow`), like a scene's `[[forces]]`.

pub mod driver;
pub mod hand;
pub mod inputs;
pub mod pacing;
pub mod page;
pub mod protocol;
pub mod replay;
pub mod server;

use crate::view::mesh::triangulate;
use crate::view::replay_data::{Camera, Floor, body_columns, camera, fall_z, floor};
use rigidsim::scene::Scene;
use serde::Serialize;

/// The `scene` message: what a client needs to draw the bodies (the
/// replay page's header, less the run's samples).
#[derive(Serialize)]
struct SceneMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    scene: &'a str,
    bodies: usize,
    dt: f64,
    frame_interval_s: f64,
    gravity: [f64; 3],
    fall_z: Option<f64>,
    camera: Option<Camera>,
    floor: Floor,
    /// Per object: name, colour (sRGB), vertices (x, y, z per vertex, body
    /// frame) and triangles (three vertex indices each, counter-clockwise
    /// seen from outside).
    objects: Vec<ObjectMessage>,
    body_object: Vec<usize>,
    body_kind: Vec<&'static str>,
    body_mass: Vec<f64>,
    /// The hand's spring (`hand`): natural frequency (rad/s) and the
    /// acceleration its force is capped at (m/s²).
    hand: HandMessage,
}

#[derive(Serialize)]
struct ObjectMessage {
    name: String,
    color: [f32; 3],
    vertices: Vec<f32>,
    indices: Vec<u32>,
}

#[derive(Serialize)]
struct HandMessage {
    frequency: f64,
    max_acceleration: f64,
}

/// The `scene` message of `scene`, as JSON text.
pub fn scene_message(scene: &Scene) -> String {
    let settings = &scene.settings;
    let (body_object, body_kind, body_mass) = body_columns(scene);
    let message = SceneMessage {
        kind: "scene",
        scene: &scene.name,
        bodies: scene.bodies.len(),
        dt: settings.dt,
        frame_interval_s: settings.frame_interval,
        gravity: settings.gravity.into(),
        fall_z: fall_z(settings),
        camera: camera(settings),
        floor: floor(scene),
        objects: scene
            .objects
            .iter()
            .map(|o| {
                let mesh = triangulate(o);
                ObjectMessage {
                    name: o.name.clone(),
                    color: o.color,
                    vertices: mesh.positions,
                    indices: mesh.indices,
                }
            })
            .collect(),
        body_object,
        body_kind,
        body_mass,
        hand: HandMessage {
            frequency: hand::frequency(settings.dt),
            max_acceleration: hand::HAND_MAX_ACCELERATION,
        },
    };
    serde_json::to_string(&message).expect("a scene message serialises")
}

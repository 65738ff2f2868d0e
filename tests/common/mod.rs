//! Shared helpers for the physics tests: scenes from TOML text, stepping.
#![allow(dead_code)]

use rigidsim::scene;
use rigidsim::step::{Inline, World};
use std::path::Path;

pub fn world(toml: &str) -> World {
    let scene = scene::from_str(toml, Path::new("test.toml"), Path::new("."))
        .unwrap_or_else(|e| panic!("{e}"));
    World::new(scene)
}

/// Steps until `time` (seconds) has been reached.
pub fn run_until(w: &mut World, exec: &mut Inline, time: f64) {
    while w.time() < time - 1e-9 {
        w.step(exec).unwrap_or_else(|e| panic!("{e}"));
    }
}

pub const FLOOR: &str = r#"
[objects.floor]
shape = { box = { half_extents = [5.0, 5.0, 0.1] } }
mass = 1.0
restitution = 1.0
friction = 0.0

[[bodies]]
object = "floor"
position = [0.0, 0.0, -0.1]
fixed = true
"#;

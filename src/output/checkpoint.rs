//! Checkpoints: the whole changing state of a `World` at the end of a step,
//! enough to continue the run bit for bit (`--checkpoint-every S`,
//! `--resume FILE`).
//!
//! What a step reads besides the static scene, and so what a checkpoint holds:
//! every body's state, kind and activity; the step count (time = steps × dt);
//! the contacts touching now (the next step's `build_islands` starts from
//! them); V-Clip's cached closest features per pair (they decide which
//! features the next query starts from, and so the last bits of its answer);
//! the resting-system timers and groups; the sleep settings; the resting
//! forces of the last solve of each touching pair (the warm start of the
//! iterative solve); and, so that the
//! summary of a resumed run reads like an uninterrupted one, the counters,
//! the largest penetration, the time each fallen body fell and the frame
//! loop's own marks (initial energy, frame index). Stage timings are wall-clock of one process and are not kept.
//!
//! The scene is not stored: every rank loads it from its file as usual, and a
//! fingerprint of what was loaded (shapes and mass properties, initial
//! bodies, forces, and the world settings that change a step, `dt` included)
//! must match the checkpoint's. A checkpoint therefore refuses a different
//! scene, a changed mesh file, or another `--dt`, but not a changed comment,
//! duration or output option.
//!
//! File layout (little-endian):
//!
//! ```text
//! 0   8 bytes  magic "RSIMCKPT"
//! 8   u32      format version (FORMAT)
//! 12  u64      payload length in bytes
//! 20  u64      FNV-1a 64 of the payload
//! 28  payload  bincode 2 (standard config, via serde) of `Checkpoint`
//! ```
//!
//! Files are written with `write_atomic` (temporary file, then rename): a run
//! killed while writing leaves the previous checkpoint whole.

use super::trajectory::TrajectoryMark;
use super::{FNV_OFFSET, fnv1a, write_atomic};
use crate::body::{Activity, Body, BodyId};
use crate::collision::narrowphase::CachedFeatures;
use crate::scene::Scene;
use crate::step::{Counters, Fall, Touching, WarmContact, World, WorldState};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub const MAGIC: &[u8; 8] = b"RSIMCKPT";
/// Bump when `Checkpoint` changes shape; older files are then refused by name.
/// 7: the counters of interaction groups (`groups`, `largest_group`,
/// `group_reruns`). 8: the time each fallen body fell (`WorldState::fallen`).
/// 9: the solver's system sizes and sweeps (`SolveStats::iterative_sweeps`,
/// `largest_rows`, `large_systems`). 10: the solver's worst violation
/// (`SolveStats::worst_violation`). 11: the interior-point solves
/// (`SolveStats::interior_solves`, `interior_steps`, `interior_missed`).
/// 12: the contact model's dial. 13: contact patches (a pair's points are
/// its patches' hull vertices, so a run resumed by an older build would
/// differ), `Counters::points_per_pair`, `speculative_pushes` and
/// `speculative_ghosts`. 14: `Counters::toi_events_by_rollback`. 15:
/// `Counters::overlap_repairs`. 16: `island_blocks`.
pub const FORMAT: u32 = 16;
const HEADER_BYTES: usize = 8 + 4 + 8 + 8;
/// File name of the checkpoint in the run's output folder.
pub const FILE_NAME: &str = "checkpoint.bin";

/// One line: `file: message`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {message}", file.display())]
pub struct CheckpointError {
    pub file: PathBuf,
    pub message: String,
}

/// What the frame loop (`run`) keeps between steps besides the world.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunMarks {
    /// Energy at t = 0 of the original run (the summary compares against it).
    pub energy_initial: f64,
    /// Index of the next frame published to the renderer.
    pub frame_index: u64,
    /// `Frame::digest` of every frame published before `frame_index`: a
    /// resumed run puts in its video only the PNGs whose mark matches.
    pub frame_digests: Vec<u64>,
    /// What `trajectory.csv` held when the checkpoint was written: a resumed
    /// run continues that file only if it still begins with those bytes.
    pub trajectory: TrajectoryMark,
}

/// The full changing state of a world at the end of a step.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Scene name and file when written (for messages only).
    pub scene_name: String,
    pub scene_path: PathBuf,
    /// `scene_fingerprint` of the scene the run was started with.
    pub scene_fingerprint: u64,
    pub dt: f64,
    /// The contact model's dial (`Settings::speculative_speed`,
    /// `Settings::pile_bodies`) the run stepped with.
    pub speculative_speed: f64,
    pub pile_bodies: u32,
    /// The blocks a large island was swept by (`Settings::island_blocks`).
    pub island_blocks: u32,
    pub steps: u64,
    pub bodies: Vec<Body>,
    pub counters: Counters,
    pub max_penetration: f64,
    pub fallen: Vec<Fall>,
    pub sleep_enabled: bool,
    pub sleep_after: f64,
    touching: Vec<Touching>,
    /// The feature cache, sorted by pair (a `HashMap` has no stable order).
    features: Vec<((u32, u32), Vec<CachedFeatures>)>,
    sleep_timer: Vec<f64>,
    sleep_group: Vec<u32>,
    last_normal_force_sum: f64,
    last_pair_forces: Vec<(BodyId, BodyId, f64)>,
    warm: Vec<((BodyId, BodyId), Vec<WarmContact>)>,
    pub run: RunMarks,
    /// Where this checkpoint was read from (not stored; names it in errors).
    #[serde(skip)]
    source: PathBuf,
}

/// A 64-bit fingerprint of everything in a loaded scene that changes how it
/// steps: gravity, dt, fall height and combine rules; every object's mass
/// properties, material, parts (vertices and faces) and broadphase spheres;
/// the initial bodies; the force windows. Duration, sampling, rendering and
/// names are left out: resuming with a longer duration is the point.
pub fn scene_fingerprint(scene: &Scene) -> u64 {
    let mut h = FNV_OFFSET;
    let mut f = |x: f64| fnv1a(&mut h, &x.to_bits().to_le_bytes());
    let s = &scene.settings;
    s.gravity.iter().for_each(|&x| f(x));
    f(s.dt);
    f(s.fall_z);
    for o in &scene.objects {
        f(o.mass);
        o.inertia.iter().for_each(|&x| f(x));
        f(o.restitution);
        f(o.friction);
        f(o.parts.len() as f64);
        for p in &o.parts {
            f(p.hull.vertices().len() as f64);
            for v in p.hull.vertices() {
                v.iter().for_each(|&x| f(x));
            }
            f(p.hull.faces().len() as f64);
            for face in p.hull.faces() {
                f(face.vertices.len() as f64);
                face.vertices.iter().for_each(|&i| f(i as f64));
            }
        }
        f(o.spheres.len() as f64);
        for sp in &o.spheres {
            sp.center.iter().for_each(|&x| f(x));
            f(sp.radius);
        }
    }
    for w in &scene.forces {
        f(w.body.0 as f64);
        w.force.iter().for_each(|&x| f(x));
        w.torque.iter().for_each(|&x| f(x));
        f(w.start);
        f(w.end);
    }
    let rules = format!("{:?}{:?}", s.restitution_rule, s.friction_rule);
    fnv1a(&mut h, rules.as_bytes());
    let bodies = bincode::serde::encode_to_vec(&scene.bodies, bincode::config::standard())
        .expect("in-memory bincode encoding cannot fail");
    fnv1a(&mut h, &bodies);
    h
}

impl World {
    /// The full state after the last completed step.
    pub fn checkpoint(&self) -> Checkpoint {
        let (s, d) = (&self.state, &self.diagnostics);
        let mut features: Vec<_> = s.features.iter().map(|(k, v)| (*k, v.clone())).collect();
        features.sort_unstable_by_key(|(k, _)| *k);
        Checkpoint {
            scene_name: self.scene.name.clone(),
            scene_path: self.scene.path.clone(),
            scene_fingerprint: scene_fingerprint(&self.scene),
            dt: self.scene.settings.dt,
            speculative_speed: self.scene.settings.speculative_speed(),
            pile_bodies: self.scene.settings.pile_bodies,
            island_blocks: self.scene.settings.island_blocks,
            steps: s.steps,
            bodies: s.bodies.clone(),
            counters: d.counters.clone(),
            max_penetration: d.max_penetration,
            fallen: s.fallen.clone(),
            sleep_enabled: self.settings.sleep_enabled,
            sleep_after: self.settings.sleep_after,
            touching: s.touching.clone(),
            features,
            sleep_timer: s.sleep_timer.clone(),
            sleep_group: s.sleep_group.clone(),
            last_normal_force_sum: d.last_normal_force_sum,
            last_pair_forces: d.last_pair_forces.clone(),
            warm: s.warm.iter().map(|(k, v)| (*k, v.clone())).collect(),
            run: RunMarks::default(),
            source: PathBuf::new(),
        }
    }

    /// The world of `scene` in the state of `ck`. Refuses a checkpoint written
    /// for another scene (or another dt), or one whose contents do not fit
    /// the scene (a damaged or hand-made file), with a message that says so.
    pub fn restore(scene: Scene, ck: Checkpoint) -> Result<World, CheckpointError> {
        ck.check_scene(&scene)?;
        ck.check_bodies(&scene)?;
        ck.check_consistent()?;
        let mut w = World::new(scene);
        w.state = WorldState {
            bodies: ck.bodies,
            steps: ck.steps,
            touching: ck.touching,
            impacts: Vec::new(),
            features: ck.features.into_iter().collect(),
            sleep_timer: ck.sleep_timer,
            sleep_group: ck.sleep_group,
            warm: ck.warm.into_iter().collect(),
            fallen: ck.fallen,
        };
        let d = &mut w.diagnostics;
        d.counters = ck.counters;
        d.max_penetration = ck.max_penetration;
        d.last_normal_force_sum = ck.last_normal_force_sum;
        d.last_pair_forces = ck.last_pair_forces;
        w.settings.sleep_enabled = ck.sleep_enabled;
        w.settings.sleep_after = ck.sleep_after;
        Ok(w)
    }
}

impl Checkpoint {
    /// The file this checkpoint was read from (empty if built in memory).
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// Simulated time of the checkpoint, seconds.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.dt
    }

    fn fail(&self, message: String) -> CheckpointError {
        CheckpointError {
            file: if self.source.as_os_str().is_empty() {
                PathBuf::from("checkpoint")
            } else {
                self.source.clone()
            },
            message,
        }
    }

    /// Refuses a scene other than the one the checkpoint was written for.
    pub fn check_scene(&self, scene: &Scene) -> Result<(), CheckpointError> {
        let s = &scene.settings;
        let dial = (s.speculative_speed(), s.pile_bodies);
        if dial != (self.speculative_speed, self.pile_bodies) {
            return Err(self.fail(format!(
                "was written with world.speculative_speed {} m/s and world.pile_bodies {}, \
                 not {} m/s and {}: resume with the contact model it was written with \
                 (the scene's settings or --speculative-speed)",
                self.speculative_speed, self.pile_bodies, dial.0, dial.1
            )));
        }
        if s.island_blocks != self.island_blocks {
            return Err(self.fail(format!(
                "was written with world.island_blocks {}, not {}: resume with the blocks \
                 it was written with (the scene's settings or --island-blocks)",
                self.island_blocks, s.island_blocks
            )));
        }
        let here = scene_fingerprint(scene);
        if here == self.scene_fingerprint {
            return Ok(());
        }
        let dt_note = if scene.settings.dt != self.dt {
            format!(
                " (dt {} s here, {} s in the checkpoint)",
                scene.settings.dt, self.dt
            )
        } else {
            String::new()
        };
        Err(self.fail(format!(
            "was written for scene '{}' ({}, fingerprint {:016x}), not for {} (fingerprint \
             {here:016x}){dt_note}: shapes, bodies, forces or world settings differ; resume \
             with the scene file and --dt it was written with",
            self.scene_name,
            self.scene_path.display(),
            self.scene_fingerprint,
            scene.path.display(),
        )))
    }

    /// Refuses a mismatch of `--no-sleep` (it changes every later step).
    pub fn check_sleep(&self, sleep_enabled: bool) -> Result<(), CheckpointError> {
        if sleep_enabled == self.sleep_enabled {
            return Ok(());
        }
        let (was, now) = if self.sleep_enabled {
            ("without", "with")
        } else {
            ("with", "without")
        };
        Err(self.fail(format!(
            "was written {was} --no-sleep but the run is {now} it; give the same option to resume"
        )))
    }

    /// Sizes and ids that must fit the scene: a file that passed the checksum
    /// but was not written by this program for this scene must not panic.
    fn check_consistent(&self) -> Result<(), CheckpointError> {
        let n = self.bodies.len();
        let bad = |what: &str| Err(self.fail(format!("is inconsistent: {what}")));
        if self.sleep_timer.len() != n || self.sleep_group.len() != n {
            return bad("resting-system tables do not match the body count");
        }
        if self.sleep_group.iter().any(|&g| g as usize >= n) {
            return bad("a resting system names a body that does not exist");
        }
        let ok_pair = |a: u32, b: u32| (a as usize) < n && (b as usize) < n && a != b;
        if self.touching.iter().any(|t| !ok_pair(t.a.0, t.b.0)) {
            return bad("a contact names a body that does not exist");
        }
        if self.features.iter().any(|((a, b), _)| !ok_pair(*a, *b)) {
            return bad("the feature cache names a body that does not exist");
        }
        let has_fallen = |f: &Fall| {
            self.bodies
                .get(f.body.index())
                .is_some_and(|b| b.activity == Activity::Fallen)
        };
        if !self.fallen.iter().all(has_fallen) {
            return bad("a fall names a body that does not exist or has not fallen");
        }
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return bad("dt is not a positive number");
        }
        for (i, b) in self.bodies.iter().enumerate() {
            let s = &b.state;
            let finite = s.position.iter().all(|x| x.is_finite())
                && s.velocity.iter().all(|x| x.is_finite())
                && s.angular_momentum.iter().all(|x| x.is_finite())
                && s.orientation.coords.iter().all(|x| x.is_finite());
            if !finite {
                return bad(&format!("body {i} has a non-finite state"));
            }
        }
        Ok(())
    }

    /// Body count and object ids must also match the scene's (checked with
    /// the scene's fingerprint; this only guards against a hand-made file
    /// whose fingerprint was copied).
    fn check_bodies(&self, scene: &Scene) -> Result<(), CheckpointError> {
        if self.bodies.len() != scene.bodies.len() {
            return Err(self.fail(format!(
                "holds {} bodies but the scene has {}",
                self.bodies.len(),
                scene.bodies.len()
            )));
        }
        for (i, (b, s)) in self.bodies.iter().zip(&scene.bodies).enumerate() {
            if b.object != s.object
                || std::mem::discriminant(&b.kind) != std::mem::discriminant(&s.kind)
            {
                return Err(self.fail(format!(
                    "body {i} is of another object or kind than in the scene"
                )));
            }
        }
        Ok(())
    }

    /// The file's bytes: header, then the bincode payload.
    pub fn to_bytes(&self) -> Vec<u8> {
        let payload = bincode::serde::encode_to_vec(self, bincode::config::standard())
            .expect("in-memory bincode encoding cannot fail");
        let mut sum = FNV_OFFSET;
        fnv1a(&mut sum, &payload);
        let mut out = Vec::with_capacity(HEADER_BYTES + payload.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&FORMAT.to_le_bytes());
        out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        out.extend_from_slice(&sum.to_le_bytes());
        out.extend_from_slice(&payload);
        out
    }

    /// Parses a checkpoint file's bytes; `file` names it in errors.
    pub fn from_bytes(bytes: &[u8], file: &Path) -> Result<Checkpoint, CheckpointError> {
        let fail = |message: String| CheckpointError {
            file: file.to_path_buf(),
            message,
        };
        if bytes.len() < HEADER_BYTES || &bytes[..8] != MAGIC {
            return Err(fail(
                "is not a rigidsim checkpoint (expected one written by --checkpoint-every)".into(),
            ));
        }
        let word = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
        let format = u32::from_le_bytes(bytes[8..12].try_into().unwrap());
        if format != FORMAT {
            return Err(fail(format!(
                "is checkpoint format {format}; this build reads format {FORMAT} only"
            )));
        }
        let (len, sum) = (word(12), word(20));
        let payload = &bytes[HEADER_BYTES..];
        if payload.len() as u64 != len {
            return Err(fail(format!(
                "is truncated or damaged ({} payload bytes, the header says {len}); use an \
                 earlier checkpoint or start over",
                payload.len()
            )));
        }
        let mut found = FNV_OFFSET;
        fnv1a(&mut found, payload);
        if found != sum {
            return Err(fail(
                "is damaged (checksum mismatch); use an earlier checkpoint or start over".into(),
            ));
        }
        let (mut ck, used) = decode_bounded(payload)
            .map_err(|e| fail(format!("cannot be decoded: {}", one_line(&e.to_string()))))?;
        if used != payload.len() {
            return Err(fail(format!(
                "has {} bytes after the state",
                payload.len() - used
            )));
        }
        ck.source = file.to_path_buf();
        ck.check_consistent()?;
        Ok(ck)
    }

    /// Reads and checks a checkpoint file (not yet against a scene).
    pub fn read(path: &Path) -> Result<Checkpoint, CheckpointError> {
        let bytes = std::fs::read(path).map_err(|e| CheckpointError {
            file: path.to_path_buf(),
            message: format!("cannot read checkpoint: {e}"),
        })?;
        Checkpoint::from_bytes(&bytes, path)
    }

    /// Reads a checkpoint and checks it against the scene and run options:
    /// what `--resume` does before any rank starts work.
    pub fn read_for(
        path: &Path,
        scene: &Scene,
        sleep_enabled: bool,
    ) -> Result<Checkpoint, CheckpointError> {
        let ck = Checkpoint::read(path)?;
        ck.check_scene(scene)?;
        ck.check_bodies(scene)?;
        ck.check_sleep(sleep_enabled)?;
        Ok(ck)
    }

    /// Writes the checkpoint atomically (temporary file, then rename).
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        write_atomic(path, &self.to_bytes())
    }
}

/// Decodes a payload with a bound on what decoding may allocate. bincode
/// allocates a string's bytes (`vec![0; len]`) from the length prefix before
/// reading them, so a damaged prefix that passed the checksum could ask for
/// 10¹⁸ bytes and abort the process. The limit counts in-memory bytes (8 per
/// f64, 8 per varint-coded u64 of one byte), at most 8× the payload for a
/// genuine file, so the bound is the first power of 16 at or above 16× the
/// payload: a hostile 1 kB file can make decoding allocate 16 MiB, no more.
fn decode_bounded(payload: &[u8]) -> Result<(Checkpoint, usize), bincode::error::DecodeError> {
    use bincode::config::standard;
    use bincode::serde::decode_from_slice;
    let need = (payload.len() as u64).saturating_mul(16);
    if need <= 1 << 24 {
        decode_from_slice(payload, standard().with_limit::<{ 1 << 24 }>())
    } else if need <= 1 << 28 {
        decode_from_slice(payload, standard().with_limit::<{ 1 << 28 }>())
    } else if need <= 1 << 32 {
        decode_from_slice(payload, standard().with_limit::<{ 1 << 32 }>())
    } else if need <= 1 << 36 {
        decode_from_slice(payload, standard().with_limit::<{ 1 << 36 }>())
    } else {
        decode_from_slice(payload, standard().with_limit::<{ 1 << 40 }>())
    }
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

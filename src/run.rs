//! One run of a scene on the coordinator (rank 0, or the only rank): the
//! frame loop around `World::step`, trajectory sampling, progress, frames
//! for the renderer, and the summary.

use crate::body::Activity;
use crate::output::capture;
use crate::output::checkpoint::{self, Checkpoint, RunMarks};
use crate::output::progress::Progress;
use crate::output::summary::{self, RankHost, RankLine, Summary};
use crate::output::trajectory::{Continued, Marking, TrajectoryWriter};
use crate::output::write_atomic;
use crate::render::{Frame, FrameSink, Pose};
use crate::scene::bounds::{self, readable};
use crate::scene::{Scene, Settings};
use crate::step::stats::{Distribution, RankSummary};
use crate::step::{Executor, Stage, World};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Command-line choices that change a run.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub out_dir: Option<PathBuf>,
    pub duration: Option<f64>,
    pub dt: Option<f64>,
    pub sample_every: Option<f64>,
    pub speculative_speed: Option<f64>,
    /// Blocks a large island is cut into (`Settings::island_blocks`).
    pub island_blocks: Option<u32>,
    pub no_render: bool,
    pub no_progress: bool,
    pub no_sleep: bool,
    /// Split large interaction groups into the parts that interact within
    /// a step (`StepSettings::split_groups`).
    pub split_groups: bool,
    /// Time the group steps' event loops (`StepSettings::time_events`).
    pub time_events: bool,
    /// Write `checkpoint.bin` every this many simulated seconds (and at the end).
    pub checkpoint_every: Option<f64>,
}

/// Applies command-line overrides to a loaded scene.
pub fn apply_overrides(scene: &mut Scene, opts: &RunOptions) -> Result<(), String> {
    if let Some(d) = opts.duration {
        if !d.is_finite() || d < 0.0 {
            return Err(format!("--duration must be a finite number ≥ 0 (got {d})"));
        }
        scene.settings.duration = Some(d);
    }
    if let Some(dt) = opts.dt {
        if !dt.is_finite() || dt <= 0.0 || dt > 1.0 {
            return Err(format!("--dt must be in (0, 1] s (got {dt})"));
        }
        scene.settings.dt = dt;
    }
    if let Some(s) = opts.sample_every {
        if !s.is_finite() || s <= 0.0 {
            return Err(format!("--sample-every must be positive (got {s})"));
        }
        scene.settings.sample_every = Some(s);
    }
    if let Some(v) = opts.speculative_speed {
        if !v.is_finite() || v < 0.0 {
            return Err(format!(
                "--speculative-speed must be a finite number ≥ 0 (got {v})"
            ));
        }
        scene.settings.speculative_speed_given = Some(v);
    }
    if let Some(n) = opts.island_blocks {
        crate::scene::check_island_blocks(n).map_err(|m| format!("--island-blocks {m}"))?;
        scene.settings.island_blocks = n;
    }
    if let Some(c) = opts.checkpoint_every {
        if !c.is_finite() || c <= 0.0 {
            return Err(format!("--checkpoint-every must be positive (got {c})"));
        }
    }
    if opts.no_render {
        scene.settings.render = None;
    }
    if opts.duration.is_some() || opts.dt.is_some() {
        if let Err(why) = bounds::check_step_count(&scene.settings) {
            let option = match (opts.duration, opts.dt) {
                (Some(d), Some(dt)) => {
                    format!("--duration {} with --dt {}", readable(d), readable(dt))
                }
                (Some(d), None) => format!("--duration {}", readable(d)),
                (None, dt) => format!("--dt {}", readable(dt.unwrap_or(scene.settings.dt))),
            };
            return Err(format!("{}: {option}: {why}", scene.path.display()));
        }
    }
    Ok(())
}

pub fn default_out_dir(scene: &Scene) -> PathBuf {
    Path::new("out").join(&scene.name)
}

pub fn frame_of(world: &World, index: u64, first_index: u64) -> Frame {
    Frame {
        index,
        first_index,
        time: world.time(),
        poses: world
            .state
            .bodies
            .iter()
            .map(|b| {
                let p = b.state.position;
                let q = b.state.orientation;
                Pose {
                    position: [p.x as f32, p.y as f32, p.z as f32],
                    orientation: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
                }
            })
            .collect(),
    }
}

/// What acts on a run between its steps besides the scene itself: nothing
/// for a plain run (`Unattended`); a person's inputs for a live run or
/// a recorded one (`rigidsim live`, `rigidsim run --inputs`).
pub trait Driver {
    /// The step the run ends at, given the scene's (`Settings::total_steps`).
    fn total_steps(&self, scene_steps: u64) -> u64 {
        scene_steps
    }
    /// Whether the run may end by coming to rest (a scene's `until_rest`).
    /// A person may still act on a world at rest, so a driven run does not.
    fn ends_at_rest(&self) -> bool {
        true
    }
    /// At the boundary before the next step (`world.steps` done): applies
    /// what is due there. `Some(reason)` ends the run at this boundary,
    /// with that `end_reason`.
    fn before_step(
        &mut self,
        _world: &mut World,
        _exec: &mut dyn Executor,
    ) -> Result<Option<&'static str>, RunError> {
        Ok(None)
    }
    /// After each step (before its sample and any checkpoint).
    fn after_step(&mut self, _world: &mut World) {}
    /// The run ended at a step boundary without a failure, before its end
    /// sample and checkpoint: what was due at this last boundary and acts
    /// on the world without a step (a recorded reset) acts now.
    fn at_end(&mut self, _world: &mut World) {}
    /// The run ended at `world.steps` for `end_reason` (outputs not yet
    /// written): notes for the summary.
    fn finish(&mut self, _world: &World, _end_reason: &str) -> Result<Vec<String>, RunError> {
        Ok(Vec::new())
    }
}

/// A plain run: nothing acts on it but the scene.
pub struct Unattended;

impl Driver for Unattended {}

/// The `end_reason`s that leave a checkpoint whatever `--checkpoint-every`
/// says: the run was ended by a person, and `--resume` continues it.
const ENDED_BY_A_PERSON: [&str; 2] = ["interrupted", "stopped"];

/// Why a run stopped early.
#[derive(Debug)]
pub enum RunError {
    Io(String),
    /// Numerical failure: the summary was written with `end_reason = "failed"`.
    Failed(String),
}

/// Runs the frame loop on the coordinator and writes every output, with
/// `driver` acting between the steps (`Unattended` for a plain run). With
/// `resume`, the run continues from that checkpoint (already checked against
/// the scene by `Checkpoint::read_for`) and the trajectory in `out_dir`, if
/// any, is continued from the checkpoint's time. `hosts` names each rank's
/// host (by rank) for `summary.json`'s `per_rank`. A signal
/// (`crate::interrupt`) ends the run at the next step boundary with
/// `end_reason = "interrupted"`.
#[allow(clippy::too_many_arguments)]
pub fn run_driven(
    scene: Scene,
    opts: &RunOptions,
    out_dir: &Path,
    exec: &mut dyn Executor,
    frames: &mut dyn FrameSink,
    resume: Option<Checkpoint>,
    hosts: &[RankHost],
    driver: &mut dyn Driver,
) -> Result<Summary, RunError> {
    std::fs::create_dir_all(out_dir)
        .map_err(|e| io(e, &format!("cannot create {}", out_dir.display())))?;
    // A summary left by an earlier run would make this folder look complete.
    let summary_path = out_dir.join("summary.json");
    let _ = std::fs::remove_file(&summary_path);
    let traj_path = out_dir.join("trajectory.csv");
    let mut notes = Vec::new();
    let units: Vec<String> = hosts.iter().map(|h| h.vector_units.clone()).collect();
    notes.extend(crate::cluster::mixed_vector_units_line(&units));

    let settings = scene.settings.clone();
    let identity = summary::scene_file_identity(&scene.path);
    let Started {
        mut world,
        marks,
        traj,
        continued,
        last_good,
    } = start_world(scene, opts, resume, &traj_path, &mut notes)?;
    // `--capture-islands`: the step keeps the islands, written after it.
    world.settings.capture_min_rows = capture::min_rows();
    let cadence = Cadence::of(&settings, opts, driver);

    let energy_initial = marks
        .as_ref()
        .map_or_else(|| world.energy(), |m| m.energy_initial);
    let mut progress = Progress::new(!opts.no_progress, cadence.end_time, &world.scene.name);
    let started = Instant::now();
    // A resumed run continues the frame numbering of the run it resumes, so
    // its frames overwrite those the stopped run drew after the checkpoint.
    let first_frame = marks.as_ref().map_or(0, |m| m.frame_index);
    // What each frame published so far drew, for the checkpoints (see
    // `FrameRenderer::replay_earlier_frames`).
    let frame_digests: Vec<u64> = marks
        .as_ref()
        .map(|m| m.frame_digests.clone())
        .unwrap_or_default();
    if cadence.render_stride.is_some() && marks.is_some() {
        frames.expect_earlier(frame_digests.clone());
    }
    let mut out = RunOutputs {
        traj,
        traj_path,
        checkpoint_path: out_dir.join(checkpoint::FILE_NAME),
        energy_initial,
        first_frame,
        frame_index: first_frame,
        frame_digests,
        last_good,
    };
    // A fresh run samples t = 0; a resumed one continues the trajectory it
    // finds (which already holds the rows up to the checkpoint) or, in a new
    // folder, starts it at the checkpoint's time.
    if continued == Continued::New {
        out.sample(&world)?;
    }
    if cadence.render_stride.is_some() && marks.is_none() {
        out.publish_timed(frames, &mut world);
    }

    let ended = frame_loop(
        &mut world,
        exec,
        frames,
        driver,
        &cadence,
        &mut out,
        &mut progress,
    )?;
    progress.finish();
    let (end_reason, worst_frame) = (ended.end_reason, ended.worst_frame);
    let failure = out.finish(&mut world, driver, &cadence, ended, &mut notes)?;
    // Simulation time ends here; waiting for the renderer to drain is render time.
    let wall = started.elapsed().as_secs_f64();
    let (ranks, drawn) = out.finish_ranks(&mut world, exec, frames, &cadence, wall, &mut notes);
    let summary = RunRecord {
        identity,
        settings: &settings,
        cadence: &cadence,
        hosts,
        energy_initial: out.energy_initial,
        worst_frame,
        wall,
    }
    .summary(&world, (end_reason, failure.clone()), ranks, drawn, notes);
    let json = serde_json::to_vec_pretty(&summary).map_err(|e| RunError::Io(e.to_string()))?;
    write_atomic(&summary_path, &json).map_err(|e| io(e, "summary.json"))?;
    match failure {
        Some(f) => Err(RunError::Failed(f)),
        None => Ok(summary),
    }
}

/// An output file's error, saying what was being written.
fn io(e: std::io::Error, what: &str) -> RunError {
    RunError::Io(format!("{what}: {e}"))
}

/// A run's world at its start, and its trajectory.
struct Started {
    world: World,
    /// What the checkpoint resumed from kept of its run.
    marks: Option<RunMarks>,
    traj: TrajectoryWriter,
    /// Whether the trajectory was started now or continued.
    continued: Continued,
    /// The checkpoint resumed from, with its time.
    last_good: Option<(PathBuf, f64)>,
}

/// The run's world, new from the scene or restored from the checkpoint
/// resumed (noted in `notes`), and its trajectory, created or continued.
fn start_world(
    scene: Scene,
    opts: &RunOptions,
    resume: Option<Checkpoint>,
    traj_path: &Path,
    notes: &mut Vec<String>,
) -> Result<Started, RunError> {
    // The last good checkpoint: the one resumed from, then each one written.
    let mut last_good: Option<(PathBuf, f64)> = None;
    // Checkpoints keep the trajectory's hash; without them it is not kept.
    let marking = if opts.checkpoint_every.is_some() {
        Marking::Hashed
    } else {
        Marking::Counted
    };
    let (world, marks, traj, continued) = match resume {
        None => {
            let mut world = World::new(scene);
            world.settings.sleep_enabled = !opts.no_sleep;
            world.settings.split_groups = opts.split_groups;
            world.settings.time_events = opts.time_events;
            let traj = TrajectoryWriter::create(traj_path, marking)
                .map_err(|e| io(e, "trajectory.csv"))?;
            (world, None, traj, Continued::New)
        }
        Some(ck) => {
            let marks = ck.run.clone();
            let time = ck.time();
            notes.push(format!(
                "resumed from {} at t = {time} s (step {})",
                ck.source().display(),
                ck.steps
            ));
            last_good = Some((ck.source().to_path_buf(), time));
            let mut world = World::restore(scene, ck).map_err(|e| RunError::Io(e.to_string()))?;
            world.settings.split_groups = opts.split_groups;
            world.settings.time_events = opts.time_events;
            let (traj, continued) =
                TrajectoryWriter::resume(traj_path, marks.trajectory, time, marking)
                    .map_err(|e| io(e, &traj_path.display().to_string()))?;
            (world, Some(marks), traj, continued)
        }
    };
    Ok(Started {
        world,
        marks,
        traj,
        continued,
        last_good,
    })
}

/// When the run ends, samples, draws, reports and checkpoints, in steps.
struct Cadence {
    end_time: f64,
    total_steps: u64,
    until_rest: bool,
    sample_stride: u64,
    frame_stride: u64,
    render_stride: Option<u64>,
    checkpoint_stride: Option<u64>,
}

impl Cadence {
    fn of(settings: &Settings, opts: &RunOptions, driver: &dyn Driver) -> Self {
        let checkpoint_stride = opts
            .checkpoint_every
            .map(|c| ((c / settings.dt).round() as u64).max(1));
        let dt = settings.dt;
        let sample_every = settings.sample_every.unwrap_or(dt);
        Cadence {
            end_time: settings.end_time(),
            total_steps: driver.total_steps(settings.total_steps()),
            until_rest: settings.until_rest && driver.ends_at_rest(),
            sample_stride: ((sample_every / dt).round() as u64).max(1),
            frame_stride: ((settings.frame_interval / dt).round() as u64).max(1),
            render_stride: settings
                .render
                .as_ref()
                .map(|r| ((r.every / dt).round() as u64).max(1)),
            checkpoint_stride,
        }
    }
}

/// What a run writes as it goes: the trajectory, the frames published so
/// far (what the checkpoints keep of them), and the last good checkpoint.
struct RunOutputs {
    traj: TrajectoryWriter,
    traj_path: PathBuf,
    checkpoint_path: PathBuf,
    energy_initial: f64,
    first_frame: u64,
    frame_index: u64,
    frame_digests: Vec<u64>,
    /// The last good checkpoint: the one resumed from, then each one written.
    last_good: Option<(PathBuf, f64)>,
}

impl RunOutputs {
    /// A trajectory row of the world as it stands.
    fn sample(&mut self, world: &World) -> Result<(), RunError> {
        self.traj
            .sample(world.time(), &world.state.bodies, &world.scene.objects)
            .map_err(|e| io(e, "trajectory.csv"))
    }

    /// Publishes a frame of the world, in the render stage's time.
    fn publish_timed(&mut self, frames: &mut dyn FrameSink, world: &mut World) {
        let timer = world.diagnostics.stage.start(Stage::Render);
        let frame = frame_of(world, self.frame_index, self.first_frame);
        self.frame_digests.truncate(self.frame_index as usize);
        self.frame_digests.push(frame.digest());
        frames.publish(frame);
        self.frame_index += 1;
        world.diagnostics.stage.stop(timer);
    }

    /// Writes the world as it stands; the trajectory is flushed first so
    /// the file holds every row up to the checkpoint's time.
    fn write_checkpoint(&mut self, world: &World) -> Result<(), RunError> {
        self.traj.flush().map_err(|e| io(e, "trajectory.csv"))?;
        let mut ck = world.checkpoint();
        ck.run = RunMarks {
            energy_initial: self.energy_initial,
            frame_index: self.frame_index,
            frame_digests: self.frame_digests.to_vec(),
            trajectory: self
                .traj
                .mark_read_back(&self.traj_path)
                .map_err(|e| io(e, &self.traj_path.display().to_string()))?,
        };
        ck.write(&self.checkpoint_path)
            .map_err(|e| io(e, &self.checkpoint_path.display().to_string()))?;
        self.last_good = Some((self.checkpoint_path.clone(), world.time()));
        Ok(())
    }

    /// The run's end at a step boundary: what the driver had due there,
    /// the end row and checkpoint (none after a failure), the trajectory
    /// flushed, and the driver's and the checkpoint's notes. Returns the
    /// failure, naming the last good checkpoint.
    fn finish(
        &mut self,
        world: &mut World,
        driver: &mut dyn Driver,
        cadence: &Cadence,
        ended: LoopEnd,
        notes: &mut Vec<String>,
    ) -> Result<Option<String>, RunError> {
        let LoopEnd {
            end_reason,
            failure,
            ..
        } = ended;
        if failure.is_none() {
            driver.at_end(world);
        }
        if failure.is_none() {
            // The end row (if the last step was not a sample). After a failure
            // the state is the broken one: the trajectory ends at the last good
            // sample, and the last checkpoint written stays as it is.
            self.sample(world)?;
            let written_now = self
                .last_good
                .as_ref()
                .is_some_and(|(p, t)| *p == self.checkpoint_path && *t == world.time());
            let keep =
                cadence.checkpoint_stride.is_some() || ENDED_BY_A_PERSON.contains(&end_reason);
            if keep && !written_now {
                self.write_checkpoint(world)?;
            }
        }
        self.traj.flush().map_err(|e| io(e, "trajectory.csv"))?;
        let failure = failure.map(|f| match &self.last_good {
            Some((p, t)) => format!("{f}; last good checkpoint: {} (t = {t} s)", p.display()),
            None if cadence.checkpoint_stride.is_some() => {
                format!("{f}; no checkpoint was written before it")
            }
            None => f,
        });
        let ended_by = if failure.is_some() {
            "failed"
        } else {
            end_reason
        };
        notes.extend(driver.finish(world, ended_by)?);
        if let Some((p, t)) = &self.last_good {
            if cadence.checkpoint_stride.is_some() || ENDED_BY_A_PERSON.contains(&end_reason) {
                notes.push(format!("last checkpoint: {} (t = {t} s)", p.display()));
            }
        }
        Ok(failure)
    }

    /// Ends the renderer (the last frame, then its drain, in render time)
    /// and the executor, with their notes: what each rank did and what
    /// was distributed, and the frames drawn, dropped and on what adapter.
    fn finish_ranks(
        &self,
        world: &mut World,
        exec: &mut dyn Executor,
        frames: &mut dyn FrameSink,
        cadence: &Cadence,
        wall: f64,
        notes: &mut Vec<String>,
    ) -> (RanksDone, Drawn) {
        let timer = world.diagnostics.stage.start(Stage::Render);
        let (frames_rendered, frames_dropped, adapter, frame_notes) =
            if cadence.render_stride.is_some() {
                frames.finish(frame_of(world, self.frame_index, self.first_frame))
            } else {
                (0, 0, None, Vec::new())
            };
        notes.extend(frame_notes);
        world.diagnostics.stage.stop(timer);
        let (mut per_rank, mut distributed) = exec.finish();
        distributed.close(wall, world.group_work());
        per_rank.extend(frames.rank_summary());
        world.diagnostics.stage.communication = per_rank.first().map_or(0.0, |r| r.waiting_s);
        for (size, e) in world.diagnostics.counters.solve.failures.iter().take(5) {
            notes.push(format!(
                "LCP solve of {size} rows failed or was rejected ({e}); a fallback solve was used"
            ));
        }
        (
            (per_rank, distributed),
            (frames_rendered, frames_dropped, adapter),
        )
    }
}

/// Each rank's summary and what was distributed (`Executor::finish`).
type RanksDone = (Vec<RankSummary>, Distribution);
/// Frames rendered, dropped, and the adapter that drew them
/// (`FrameSink::finish`).
type Drawn = (u64, u64, Option<String>);

/// How the frame loop ended.
struct LoopEnd {
    end_reason: &'static str,
    /// The numerical failure that stopped it, if one did.
    failure: Option<String>,
    /// The longest wall time a frame's steps took.
    worst_frame: f64,
}

/// The frame loop: steps until the run's end (its last step, rest, a
/// signal, the driver, or a failure), sampling, drawing, checkpointing
/// and reporting progress at their strides.
fn frame_loop(
    world: &mut World,
    exec: &mut dyn Executor,
    frames: &mut dyn FrameSink,
    driver: &mut dyn Driver,
    cadence: &Cadence,
    out: &mut RunOutputs,
    progress: &mut Progress,
) -> Result<LoopEnd, RunError> {
    let total_steps = cadence.total_steps;
    let mut frame_started = Instant::now();
    let mut worst_frame: f64 = 0.0;
    let mut end_reason = "duration";
    let mut failure = None;
    while world.state.steps < total_steps {
        if crate::interrupt::requested().is_some() {
            end_reason = "interrupted";
            break;
        }
        if cadence.until_rest && world.state.steps > 0 && world.at_rest() {
            end_reason = "rest";
            break;
        }
        if let Some(reason) = driver.before_step(world, exec)? {
            end_reason = reason;
            break;
        }
        let stepped = world.step(exec);
        // Also after a failure: its islands are the ones to look at.
        capture::islands(&world.diagnostics.captured_islands);
        if let Err(f) = stepped {
            failure = Some(f.to_string());
            break;
        }
        driver.after_step(world);
        let s = world.state.steps;
        if s % cadence.sample_stride == 0 || s == total_steps {
            out.sample(world)?;
        }
        if let Some(stride) = cadence.render_stride {
            if s % stride == 0 {
                out.publish_timed(frames, world);
            }
        }
        if cadence.checkpoint_stride.is_some_and(|k| s % k == 0) {
            out.write_checkpoint(world)?;
        }
        if s % cadence.frame_stride == 0 {
            worst_frame = worst_frame.max(frame_started.elapsed().as_secs_f64());
            frame_started = Instant::now();
            let awake = world
                .state
                .bodies
                .iter()
                .filter(|b| b.activity == Activity::Awake && b.is_dynamic())
                .count();
            progress.update(world.time(), awake, world.state.bodies.len());
        }
    }
    if failure.is_none() && end_reason == "duration" && cadence.until_rest && world.at_rest() {
        end_reason = "rest";
    }
    if world.state.steps % cadence.frame_stride != 0 {
        // The last, partial frame.
        worst_frame = worst_frame.max(frame_started.elapsed().as_secs_f64());
    }
    Ok(LoopEnd {
        end_reason,
        failure,
        worst_frame,
    })
}

/// What a run's summary is made of besides the world at its end.
struct RunRecord<'a> {
    /// The scene file's path and digest (`summary::scene_file_identity`).
    identity: (Option<String>, Option<String>),
    settings: &'a Settings,
    cadence: &'a Cadence,
    hosts: &'a [RankHost],
    energy_initial: f64,
    worst_frame: f64,
    wall: f64,
}

impl RunRecord<'_> {
    /// The run's summary (`summary.json`).
    fn summary(
        self,
        world: &World,
        (end_reason, failure): (&str, Option<String>),
        (per_rank, distributed): RanksDone,
        (frames_rendered, frames_dropped, adapter): Drawn,
        notes: Vec<String>,
    ) -> Summary {
        let (scene_path, scene_digest) = self.identity;
        let wall = self.wall;
        Summary {
            scene: world.scene.name.clone(),
            scene_path,
            scene_digest,
            ranks: per_rank.len() as u32,
            bodies: world.state.bodies.len(),
            steps: world.state.steps,
            sim_time_s: world.time(),
            wall_time_s: wall,
            dt_s: self.settings.dt,
            frame_interval_s: self.settings.frame_interval,
            worst_frame_s: self.worst_frame,
            realtime_factor: if wall > 0.0 { world.time() / wall } else { 0.0 },
            end_reason: if failure.is_some() {
                "failed".into()
            } else {
                end_reason.into()
            },
            failure,
            max_penetration_m: world.diagnostics.max_penetration,
            energy_initial_j: self.energy_initial,
            energy_final_j: world.energy(),
            stage_seconds: world.diagnostics.stage.clone(),
            per_rank: per_rank
                .into_iter()
                .map(|r| {
                    RankLine::new(
                        r,
                        self.hosts,
                        world.state.steps.div_ceil(self.cadence.frame_stride),
                    )
                })
                .collect(),
            state_hash: world.state_hash(),
            counters: world.diagnostics.counters.clone(),
            bodies_resting: world
                .state
                .bodies
                .iter()
                .filter(|b| b.activity == Activity::Sleeping)
                .count(),
            bodies_fallen: world
                .state
                .bodies
                .iter()
                .filter(|b| b.activity == Activity::Fallen)
                .count(),
            fallen: world.state.fallen.clone(),
            distributed,
            frames_rendered,
            frames_dropped,
            render_adapter: adapter,
            notes,
        }
    }
}

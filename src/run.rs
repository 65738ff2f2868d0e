//! One run of a scene on the coordinator (rank 0, or the only rank): the
//! frame loop around `World::step`, trajectory sampling, progress, frames
//! for the renderer, and the summary.

use crate::body::{Activity, BodyKind};
use crate::output::checkpoint::{self, Checkpoint, RunMarks};
use crate::output::progress::Progress;
use crate::output::summary::{self, RankHost, RankLine, RankSummary, Summary};
use crate::output::trajectory::{Continued, Marking, TrajectoryWriter};
use crate::output::{FNV_OFFSET, fnv1a, write_atomic};
use crate::render;
use crate::scene::Scene;
use crate::scene::bounds::{self, readable};
use crate::step::{Executor, World};
use serde::{Deserialize, Serialize};
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
    pub no_render: bool,
    pub no_progress: bool,
    pub no_sleep: bool,
    /// Split large interaction groups into the parts that interact within
    /// a step (`World::split_groups`).
    pub split_groups: bool,
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

/// One body's pose as the renderer needs it (render message, SPEC 3.4).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Pose {
    pub position: [f32; 3],
    pub orientation: [f32; 4],
}

/// A frame of poses for the renderer.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Frame {
    pub index: u64,
    /// The index of the first frame this run publishes: 0, or on a resumed
    /// run the checkpoint's next frame index. Every frame carries it because
    /// the render rank never sees the checkpoint, and the first frame it
    /// receives may not be the run's first (frames can be dropped).
    pub first_index: u64,
    pub time: f64,
    pub poses: Vec<Pose>,
}

impl Frame {
    /// FNV-1a 64 of the frame's index and poses: the same on rank 0, which
    /// keeps it in checkpoints, and on the rank that draws the frame.
    pub fn digest(&self) -> u64 {
        let mut h = FNV_OFFSET;
        fnv1a(&mut h, &self.index.to_le_bytes());
        for p in &self.poses {
            for x in p.position.iter().chain(&p.orientation) {
                fnv1a(&mut h, &x.to_le_bytes());
            }
        }
        h
    }

    /// The text its PNG carries under `render::FRAME_MARK_KEY`.
    pub fn mark(&self) -> String {
        frame_mark(self.index, self.digest())
    }
}

fn frame_mark(index: u64, digest: u64) -> String {
    format!("frame {index} poses {digest:016x}")
}

pub fn frame_of(world: &World, index: u64, first_index: u64) -> Frame {
    Frame {
        index,
        first_index,
        time: world.time(),
        poses: world
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

/// Where frames go: nowhere, a renderer on this rank, or the render rank.
pub trait FrameSink {
    fn publish(&mut self, frame: Frame);
    /// A resumed run, before its first frame: the digests of the frames
    /// `0..first` the run it continues published.
    fn expect_earlier(&mut self, _digests: Vec<u64>) {}
    /// Ends the stream; returns (frames rendered, frames dropped, adapter, notes).
    fn finish(&mut self, last: Frame) -> (u64, u64, Option<String>, Vec<String>);
    /// The render rank's line in `per_rank`, when frames go to another rank.
    fn rank_summary(&self) -> Option<RankSummary> {
        None
    }
    /// Why the frames' destination stopped answering, if it did (the render
    /// rank, in `finish`): the job must then end without it.
    fn lost(&self) -> Option<String> {
        None
    }
}

pub struct NoFrames;

impl FrameSink for NoFrames {
    fn publish(&mut self, _frame: Frame) {}
    fn finish(&mut self, _last: Frame) -> (u64, u64, Option<String>, Vec<String>) {
        (0, 0, None, Vec::new())
    }
}

/// Draws frames: used by the render rank, and inline on a single rank.
pub struct FrameRenderer {
    renderer: render::Renderer,
    camera: render::Camera,
    instances: Vec<render::Instance>,
    dir: PathBuf,
    video: Option<render::VideoWriter>,
    /// Whether `video` has been given the frames of the run this one resumes
    /// (see [`FrameRenderer::replay_earlier_frames`]).
    replayed: bool,
    /// `Frame::digest` of each frame the resumed run published.
    earlier: Vec<u64>,
    pub rendered: u64,
    pub notes: Vec<String>,
}

/// Where frame `index` is written: `frames/frame_00042.png`.
fn frame_path(dir: &Path, index: u64) -> PathBuf {
    dir.join(format!("frame_{index:05}.png"))
}

impl FrameRenderer {
    pub fn new(scene: &Scene, out_dir: &Path) -> Result<FrameRenderer, String> {
        let settings = scene
            .settings
            .render
            .as_ref()
            .ok_or("the scene has no [render] section")?;
        let meshes: Vec<render::Mesh> = scene
            .objects
            .iter()
            .map(|o| {
                let mut positions = Vec::new();
                let mut indices = Vec::new();
                for p in &o.parts {
                    let base = positions.len() as u32;
                    positions.extend(
                        p.hull
                            .vertices()
                            .iter()
                            .map(|v| [v.x as f32, v.y as f32, v.z as f32]),
                    );
                    for t in p.hull.triangles() {
                        indices.extend(t.iter().map(|&i| base + i as u32));
                    }
                }
                render::Mesh { positions, indices }
            })
            .collect();
        let renderer = render::Renderer::new(settings.size[0], settings.size[1], meshes)
            .map_err(|e| e.to_string())?;
        let instances: Vec<render::Instance> = scene
            .bodies
            .iter()
            .map(|b| render::Instance {
                mesh: b.object.0 as usize,
                rotation: [1.0, 0.0, 0.0, 0.0],
                translation: [0.0; 3],
                color: scene.objects[b.object.0 as usize].color,
                fixed: matches!(b.kind, BodyKind::Fixed),
            })
            .collect();
        let camera = match (settings.eye, settings.target) {
            (Some(e), Some(t)) => {
                let mut c = render::Camera::looking_at(
                    [e.x as f32, e.y as f32, e.z as f32],
                    [t.x as f32, t.y as f32, t.z as f32],
                );
                c.fov_y_deg = settings.fov_y_deg as f32;
                c
            }
            _ => {
                let points: Vec<[f32; 3]> = scene
                    .bodies
                    .iter()
                    .flat_map(|b| {
                        let o = &scene.objects[b.object.0 as usize];
                        o.spheres.iter().flat_map(move |s| {
                            let c = b.state.position + b.state.orientation * s.center;
                            let r = s.radius;
                            [
                                [(c.x - r) as f32, (c.y - r) as f32, (c.z - r) as f32],
                                [(c.x + r) as f32, (c.y + r) as f32, (c.z + r) as f32],
                            ]
                        })
                    })
                    .collect();
                render::look_at_scene(&points)
            }
        };
        let dir = out_dir.join("frames");
        std::fs::create_dir_all(&dir)
            .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
        let mut notes = Vec::new();
        let fps = settings.video_fps.round().max(1.0) as u32;
        let video = render::VideoWriter::start(
            out_dir.join("video.mp4"),
            settings.size[0],
            settings.size[1],
            fps,
        )
        .map_err(|e| e.to_string())?;
        if video.is_none() {
            let note = "ffmpeg not found: no video.mp4, frames kept as PNG".to_string();
            eprintln!("rigidsim: {note}");
            notes.push(note);
        }
        Ok(FrameRenderer {
            renderer,
            camera,
            instances,
            dir,
            video,
            replayed: false,
            earlier: Vec::new(),
            rendered: 0,
            notes,
        })
    }

    pub fn adapter(&self) -> String {
        self.renderer.adapter_info()
    }

    pub fn draw(&mut self, frame: &Frame) -> Result<render::Image, String> {
        for (inst, pose) in self.instances.iter_mut().zip(&frame.poses) {
            inst.translation = pose.position;
            inst.rotation = pose.orientation;
        }
        self.renderer
            .render(&self.camera, &self.instances)
            .map_err(|e| e.to_string())
    }

    /// The digests of the frames the resumed run published (see
    /// `replay_earlier_frames`).
    pub fn expect_earlier(&mut self, digests: Vec<u64>) {
        self.earlier = digests;
    }

    pub fn render_frame(&mut self, frame: &Frame) -> Result<(), String> {
        self.replay_earlier_frames(frame.first_index, &mut || {});
        let image = self.draw(frame)?;
        let path = frame_path(&self.dir, frame.index);
        render::write_png_marked(&path, &image, Some(&frame.mark())).map_err(|e| e.to_string())?;
        if let Some(v) = self.video.as_mut() {
            v.push(&image).map_err(|e| e.to_string())?;
        }
        self.rendered += 1;
        Ok(())
    }

    /// Writes `preview.png` of the final state and closes the video.
    /// `alive` is called after each earlier frame replayed into the video
    /// (the render rank's sign of life while it finishes).
    pub fn finish(&mut self, last: &Frame, alive: &mut dyn FnMut()) -> Result<(), String> {
        let image = self.draw(last)?;
        let preview = self
            .dir
            .parent()
            .unwrap_or(Path::new("."))
            .join("preview.png");
        render::write_png(&preview, &image).map_err(|e| e.to_string())?;
        // A run resumed at its very end publishes no frame: its video is
        // still the whole of the earlier run's.
        self.replay_earlier_frames(last.first_index, alive);
        if let Some(v) = self.video.take() {
            v.finish().map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// Feeds the new video the frames `0..first` that the run this one
    /// resumes left in `frames/`, once, before this run's first frame.
    ///
    /// ffmpeg cannot append to an MP4, so a resumed run's `video.mp4` is a
    /// new stream; without this it would hold only the frames after the
    /// checkpoint. Frames are read back from the PNGs rather than re-rendered
    /// because only the checkpoint's state is known, not the earlier ones.
    /// Frames the stopped run wrote after its checkpoint have indices
    /// `first` and up: this run renders (and overwrites) them again, so they
    /// are not read. A missing or unreadable file is left out and reported
    /// in one note; it never stops the run. Without ffmpeg nothing is read.
    ///
    /// Each PNG must carry the mark of the frame the checkpoint's run
    /// published at its index (`Frame::mark`, digests from
    /// `expect_earlier`): a frame drawn by another run in the same folder,
    /// or left from before a frame the renderer dropped, is left out too.
    fn replay_earlier_frames(&mut self, first: u64, alive: &mut dyn FnMut()) {
        if self.replayed {
            return;
        }
        self.replayed = true;
        let Some(video) = self.video.as_mut() else {
            return;
        };
        let mut left_out = 0u64;
        let mut first_problem = None;
        for index in 0..first {
            alive();
            let path = frame_path(&self.dir, index);
            let expected = self
                .earlier
                .get(index as usize)
                .map(|&d| frame_mark(index, d));
            let problem = match render::read_png_marked(&path) {
                Ok((_, mark)) if mark.is_none() || mark != expected => format!(
                    "{}: not this run's frame (marked {:?}, the checkpoint expects {:?})",
                    path.display(),
                    mark.unwrap_or_else(|| "nothing".into()),
                    expected.unwrap_or_else(|| "no frame".into())
                ),
                Ok((image, _)) => match video.push(&image) {
                    Ok(()) => continue,
                    // The scene's [render] size changed between the runs.
                    Err(e @ render::RenderError::FrameSize { .. }) => {
                        format!("{}: {e}", path.display())
                    }
                    // ffmpeg itself failed; the frames this run renders
                    // will report it too.
                    Err(e) => {
                        self.notes.push(format!(
                            "video.mp4: stopped adding the frames before frame {first}: {e}"
                        ));
                        return;
                    }
                },
                Err(e) => e.to_string(),
            };
            left_out += 1;
            first_problem.get_or_insert(problem);
        }
        if let Some(problem) = first_problem {
            let note = format!(
                "video.mp4: {left_out} of the {first} frames before the resumed run's first \
                 (frame {first}) are missing, unusable or not this run's in {} and were left out; \
                 first: {problem}",
                self.dir.display()
            );
            eprintln!("rigidsim: {note}");
            self.notes.push(note);
        }
    }
}

/// Renders on this rank after each frame (one rank with rendering on).
pub struct InlineFrames(pub FrameRenderer);

impl FrameSink for InlineFrames {
    fn expect_earlier(&mut self, digests: Vec<u64>) {
        self.0.expect_earlier(digests);
    }
    fn publish(&mut self, frame: Frame) {
        if let Err(e) = self.0.render_frame(&frame) {
            self.0
                .notes
                .push(format!("frame {} not rendered: {e}", frame.index));
        }
    }
    fn finish(&mut self, last: Frame) -> (u64, u64, Option<String>, Vec<String>) {
        if let Err(e) = self.0.finish(&last, &mut || {}) {
            self.0.notes.push(format!("preview not rendered: {e}"));
        }
        (
            self.0.rendered,
            0,
            Some(self.0.adapter()),
            self.0.notes.clone(),
        )
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

/// Runs the frame loop on the coordinator and writes every output. With
/// `resume`, the run continues from that checkpoint (already checked against
/// the scene by `Checkpoint::read_for`) and the trajectory in `out_dir`, if
/// any, is continued from the checkpoint's time. `hosts` names each rank's
/// host (by rank) for `summary.json`'s `per_rank`.
pub fn run_coordinator(
    scene: Scene,
    opts: &RunOptions,
    out_dir: &Path,
    exec: &mut dyn Executor,
    frames: &mut dyn FrameSink,
    resume: Option<Checkpoint>,
    hosts: &[RankHost],
) -> Result<Summary, RunError> {
    run_driven(
        scene,
        opts,
        out_dir,
        exec,
        frames,
        resume,
        hosts,
        &mut Unattended,
    )
}

/// `run_coordinator` with a `Driver` acting between the steps. A signal
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
    let io = |e: std::io::Error, what: &str| RunError::Io(format!("{what}: {e}"));
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
    let (scene_path, scene_digest) = summary::scene_file_identity(&scene.path);
    // The last good checkpoint: the one resumed from, then each one written.
    let mut last_good: Option<(PathBuf, f64)> = None;
    // Checkpoints keep the trajectory's hash; without them it is not kept.
    let marking = if opts.checkpoint_every.is_some() {
        Marking::Hashed
    } else {
        Marking::Counted
    };
    let (mut world, marks, mut traj, continued) = match resume {
        None => {
            let mut world = World::new(scene);
            world.sleep_enabled = !opts.no_sleep;
            world.split_groups = opts.split_groups;
            let traj = TrajectoryWriter::create(&traj_path, marking)
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
            world.split_groups = opts.split_groups;
            let (traj, continued) =
                TrajectoryWriter::resume(&traj_path, marks.trajectory, time, marking)
                    .map_err(|e| io(e, &traj_path.display().to_string()))?;
            (world, Some(marks), traj, continued)
        }
    };
    let checkpoint_path = out_dir.join(checkpoint::FILE_NAME);
    let checkpoint_stride = opts
        .checkpoint_every
        .map(|c| ((c / settings.dt).round() as u64).max(1));
    let dt = settings.dt;
    let end_time = settings.end_time();
    let total_steps = driver.total_steps(settings.total_steps());
    let until_rest = settings.until_rest && driver.ends_at_rest();
    let sample_every = settings.sample_every.unwrap_or(dt);
    let sample_stride = ((sample_every / dt).round() as u64).max(1);
    let frame_stride = ((settings.frame_interval / dt).round() as u64).max(1);
    let render_stride = settings
        .render
        .as_ref()
        .map(|r| ((r.every / dt).round() as u64).max(1));

    let energy_initial = marks
        .as_ref()
        .map_or_else(|| world.energy(), |m| m.energy_initial);
    let mut progress = Progress::new(!opts.no_progress, end_time, &world.scene.name);
    let started = Instant::now();
    let mut frame_started = Instant::now();
    let mut worst_frame: f64 = 0.0;
    // A resumed run continues the frame numbering of the run it resumes, so
    // its frames overwrite those the stopped run drew after the checkpoint.
    let first_frame = marks.as_ref().map_or(0, |m| m.frame_index);
    let mut frame_index = first_frame;
    // What each frame published so far drew, for the checkpoints (see
    // `FrameRenderer::replay_earlier_frames`).
    let mut frame_digests: Vec<u64> = marks
        .as_ref()
        .map(|m| m.frame_digests.clone())
        .unwrap_or_default();
    if render_stride.is_some() && marks.is_some() {
        frames.expect_earlier(frame_digests.clone());
    }
    let publish =
        |frames: &mut dyn FrameSink, world: &World, index: &mut u64, digests: &mut Vec<u64>| {
            let frame = frame_of(world, *index, first_frame);
            digests.truncate(*index as usize);
            digests.push(frame.digest());
            frames.publish(frame);
            *index += 1;
        };
    // A fresh run samples t = 0; a resumed one continues the trajectory it
    // finds (which already holds the rows up to the checkpoint) or, in a new
    // folder, starts it at the checkpoint's time.
    if continued == Continued::New {
        traj.sample(world.time(), &world.bodies, &world.scene.objects)
            .map_err(|e| io(e, "trajectory.csv"))?;
    }
    if render_stride.is_some() && marks.is_none() {
        let clock = Instant::now();
        publish(frames, &world, &mut frame_index, &mut frame_digests);
        world.stage.render += clock.elapsed().as_secs_f64();
    }
    // Writes the world as it stands; the trajectory is flushed first so the
    // file holds every row up to the checkpoint's time.
    let write_checkpoint = |world: &World,
                            frame_index: u64,
                            frame_digests: &[u64],
                            traj: &mut TrajectoryWriter|
     -> Result<_, RunError> {
        traj.flush().map_err(|e| io(e, "trajectory.csv"))?;
        let mut ck = world.checkpoint();
        ck.run = RunMarks {
            energy_initial,
            frame_index,
            frame_digests: frame_digests.to_vec(),
            trajectory: traj
                .mark_read_back(&traj_path)
                .map_err(|e| io(e, &traj_path.display().to_string()))?,
        };
        ck.write(&checkpoint_path)
            .map_err(|e| io(e, &checkpoint_path.display().to_string()))?;
        Ok(Some((checkpoint_path.clone(), world.time())))
    };

    let mut end_reason = "duration";
    let mut failure = None;
    while world.steps < total_steps {
        if crate::interrupt::requested().is_some() {
            end_reason = "interrupted";
            break;
        }
        if until_rest && world.steps > 0 && world.at_rest() {
            end_reason = "rest";
            break;
        }
        if let Some(reason) = driver.before_step(&mut world, exec)? {
            end_reason = reason;
            break;
        }
        if let Err(f) = world.step(exec) {
            failure = Some(f.to_string());
            break;
        }
        driver.after_step(&mut world);
        let s = world.steps;
        if s % sample_stride == 0 || s == total_steps {
            traj.sample(world.time(), &world.bodies, &world.scene.objects)
                .map_err(|e| io(e, "trajectory.csv"))?;
        }
        if let Some(stride) = render_stride {
            if s % stride == 0 {
                let clock = Instant::now();
                publish(frames, &world, &mut frame_index, &mut frame_digests);
                world.stage.render += clock.elapsed().as_secs_f64();
            }
        }
        if checkpoint_stride.is_some_and(|k| s % k == 0) {
            last_good = write_checkpoint(&world, frame_index, &frame_digests, &mut traj)?;
        }
        if s % frame_stride == 0 {
            worst_frame = worst_frame.max(frame_started.elapsed().as_secs_f64());
            frame_started = Instant::now();
            let awake = world
                .bodies
                .iter()
                .filter(|b| b.activity == Activity::Awake && b.is_dynamic())
                .count();
            progress.update(world.time(), awake, world.bodies.len());
        }
    }
    if failure.is_none() && end_reason == "duration" && until_rest && world.at_rest() {
        end_reason = "rest";
    }
    if world.steps % frame_stride != 0 {
        // The last, partial frame.
        worst_frame = worst_frame.max(frame_started.elapsed().as_secs_f64());
    }
    progress.finish();
    if failure.is_none() {
        driver.at_end(&mut world);
    }
    if failure.is_none() {
        // The end row (if the last step was not a sample). After a failure
        // the state is the broken one: the trajectory ends at the last good
        // sample, and the last checkpoint written stays as it is.
        traj.sample(world.time(), &world.bodies, &world.scene.objects)
            .map_err(|e| io(e, "trajectory.csv"))?;
        let written_now = last_good
            .as_ref()
            .is_some_and(|(p, t)| *p == checkpoint_path && *t == world.time());
        let keep = checkpoint_stride.is_some() || ENDED_BY_A_PERSON.contains(&end_reason);
        if keep && !written_now {
            last_good = write_checkpoint(&world, frame_index, &frame_digests, &mut traj)?;
        }
    }
    traj.flush().map_err(|e| io(e, "trajectory.csv"))?;
    let failure = failure.map(|f| match &last_good {
        Some((p, t)) => format!("{f}; last good checkpoint: {} (t = {t} s)", p.display()),
        None if checkpoint_stride.is_some() => format!("{f}; no checkpoint was written before it"),
        None => f,
    });
    let ended_by = if failure.is_some() {
        "failed"
    } else {
        end_reason
    };
    notes.extend(driver.finish(&world, ended_by)?);
    if let Some((p, t)) = &last_good {
        if checkpoint_stride.is_some() || ENDED_BY_A_PERSON.contains(&end_reason) {
            notes.push(format!("last checkpoint: {} (t = {t} s)", p.display()));
        }
    }
    // Simulation time ends here; waiting for the renderer to drain is render time.
    let wall = started.elapsed().as_secs_f64();
    let clock = Instant::now();
    let (frames_rendered, frames_dropped, adapter, frame_notes) = if render_stride.is_some() {
        frames.finish(frame_of(&world, frame_index, first_frame))
    } else {
        (0, 0, None, Vec::new())
    };
    notes.extend(frame_notes);
    world.stage.render += clock.elapsed().as_secs_f64();
    let (mut per_rank, mut distributed) = exec.finish();
    distributed.close(wall, world.group_work());
    per_rank.extend(frames.rank_summary());
    world.stage.communication = per_rank.first().map_or(0.0, |r| r.waiting_s);
    for (size, e) in world.counters.solve.failures.iter().take(5) {
        notes.push(format!(
            "LCP solve of {size} rows failed or was rejected ({e}); a fallback solve was used"
        ));
    }

    let summary = Summary {
        scene: world.scene.name.clone(),
        scene_path,
        scene_digest,
        ranks: per_rank.len() as u32,
        bodies: world.bodies.len(),
        steps: world.steps,
        sim_time_s: world.time(),
        wall_time_s: wall,
        dt_s: dt,
        frame_interval_s: settings.frame_interval,
        worst_frame_s: worst_frame,
        realtime_factor: if wall > 0.0 { world.time() / wall } else { 0.0 },
        end_reason: if failure.is_some() {
            "failed".into()
        } else {
            end_reason.into()
        },
        failure: failure.clone(),
        max_penetration_m: world.max_penetration,
        energy_initial_j: energy_initial,
        energy_final_j: world.energy(),
        stage_seconds: world.stage.clone(),
        per_rank: per_rank
            .into_iter()
            .map(|r| RankLine::new(r, hosts, world.steps.div_ceil(frame_stride)))
            .collect(),
        state_hash: world.state_hash(),
        counters: world.counters.clone(),
        bodies_resting: world
            .bodies
            .iter()
            .filter(|b| b.activity == Activity::Sleeping)
            .count(),
        bodies_fallen: world
            .bodies
            .iter()
            .filter(|b| b.activity == Activity::Fallen)
            .count(),
        fallen: world.fallen.clone(),
        distributed,
        frames_rendered,
        frames_dropped,
        render_adapter: adapter,
        notes,
    };
    let json = serde_json::to_vec_pretty(&summary).map_err(|e| RunError::Io(e.to_string()))?;
    write_atomic(&summary_path, &json).map_err(|e| io(e, "summary.json"))?;
    match failure {
        Some(f) => Err(RunError::Failed(f)),
        None => Ok(summary),
    }
}

//! Frames drawn from a scene's bodies (`FrameRenderer`): by the render rank,
//! or inline on a single rank (`InlineFrames`).

use super::frame::{Frame, FrameSink, frame_mark};
use crate::body::BodyKind;
use crate::render;
use crate::scene::Scene;
use std::path::{Path, PathBuf};

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

//! Off-screen renderer of the render rank (SPEC 3.1, 3.4).
//!
//! The last MPI rank receives each body's pose at every screen update and
//! draws it here: headless wgpu (no window, no surface), read back into an
//! [`Image`], then written as PNG ([`write_png`]) or streamed to ffmpeg
//! ([`VideoWriter`]); [`read_png`] reads a frame back for a resumed run's
//! video. The renderer knows nothing of scenes or MPI: it takes
//! plain meshes, poses and colours, so the rank that owns it can be tested
//! on its own. The frames rank 0 publishes ([`Frame`], [`FrameSink`]) and
//! their drawing from a scene's bodies ([`FrameRenderer`]) are in `frame.rs`
//! and `frame_renderer.rs`.
//!
//! Frame recipe, in the order [`Renderer::render`] runs it:
//! 1. instances are grouped by mesh (counting sort) into one instance buffer;
//! 2. one draw per mesh kind, each instanced over all bodies of that kind;
//!    closed meshes are re-wound outward at upload and back-face culled
//!    (half lavapipe's work), open ones drawn two-sided;
//! 3. depth-tested (reversed Z); 4x MSAA on real GPUs only, since on CPU
//!    adapters it triples the frame time;
//! 4. flat Lambert shading: per-face normals, one key light from above, on
//!    the viewer's side and a little to the left, plus 30 % ambient;
//! 5. the resolved image is copied to a mapped buffer and de-padded.
//!
//! Looks: background [`BACKGROUND`] (pale blue-grey), bodies in their own
//! colour; fixed bodies get a body-frame checker whose alternate cells are
//! at [`FIXED_CHECKER_DARKEN`] brightness, so a fixed floor never reads as
//! one more free box.

mod camera;
mod frame;
mod frame_renderer;
mod gpu;
mod image;
mod mesh;
mod video;

use std::path::PathBuf;

pub use camera::{Camera, look_at_scene};
pub use frame::{Frame, FrameSink, NoFrames, Pose};
pub use frame_renderer::{FrameRenderer, InlineFrames};
pub use gpu::Renderer;
pub use image::{FRAME_MARK_KEY, Image, read_png, read_png_marked, write_png, write_png_marked};
pub use mesh::Mesh;
pub use video::VideoWriter;

/// Clear colour of every frame, RGBA8. Exact in the output: pixels that no
/// triangle touches keep it byte for byte (tests rely on that).
pub const BACKGROUND: [u8; 4] = [232, 236, 242, 255];

/// Brightness of the darker cells of a fixed body's checker, relative to the
/// lit colour of the lighter cells.
pub const FIXED_CHECKER_DARKEN: f32 = 0.7;

/// One body to draw: which mesh, its pose in the world, its look.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index into the meshes given to [`Renderer::new`].
    pub mesh: usize,
    /// Orientation as a quaternion `[w, x, y, z]`; need not be normalised.
    pub rotation: [f32; 4],
    /// Position of the body frame's origin in the world.
    pub translation: [f32; 3],
    /// Linear RGB in `[0, 1]`, used as display values (no gamma step).
    pub color: [f32; 3],
    /// Fixed (static) bodies are drawn with a checker.
    pub fixed: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(
        "no graphics adapter (Vulkan or GL) found: {0}; install mesa-vulkan-drivers \
         (lavapipe, a CPU Vulkan driver) or run with --no-render"
    )]
    NoAdapter(String),
    #[error("the adapter {adapter} refused to open a device: {message}")]
    RequestDevice { adapter: String, message: String },
    #[error("image size {width}x{height} is not allowed: {reason}")]
    BadSize {
        width: u32,
        height: u32,
        reason: String,
    },
    #[error("mesh {mesh}: {reason}")]
    BadMesh { mesh: usize, reason: String },
    #[error("instance {instance} uses mesh {mesh}, but only {mesh_count} meshes were uploaded")]
    UnknownMesh {
        instance: usize,
        mesh: usize,
        mesh_count: usize,
    },
    #[error("instance {instance}: {reason}")]
    BadInstance { instance: usize, reason: String },
    #[error("camera is unusable: {0}")]
    BadCamera(String),
    #[error("GPU error while {stage}: {message}")]
    Gpu {
        stage: &'static str,
        message: String,
    },
    #[error("frame is {got_width}x{got_height}, but the video was started as {width}x{height}")]
    FrameSize {
        width: u32,
        height: u32,
        got_width: u32,
        got_height: u32,
    },
    #[error("{what} {}: {source}", path.display())]
    Io {
        what: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("writing PNG {}: {source}", path.display())]
    Png {
        path: PathBuf,
        source: png::EncodingError,
    },
    #[error("reading PNG {}: {reason}", path.display())]
    PngRead { path: PathBuf, reason: String },
    #[error("ffmpeg failed on {}: {message}", path.display())]
    Ffmpeg { path: PathBuf, message: String },
}

use std::io::{ErrorKind, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::thread::JoinHandle;

use super::{BACKGROUND, Image, RenderError};

/// How much of ffmpeg's stderr is kept for error messages.
const STDERR_TAIL: usize = 4096;

/// Streams frames to an `ffmpeg` child as raw RGBA on its stdin, encoded to
/// H.264 (libx264, `yuv420p`, so any player can open the file).
///
/// `yuv420p` halves the chroma resolution, so libx264 needs an even width and
/// height: an odd dimension is padded by one row or column of [`BACKGROUND`]
/// colour inside ffmpeg; frames are always pushed at the size given to
/// [`VideoWriter::start`].
pub struct VideoWriter {
    path: PathBuf,
    width: u32,
    height: u32,
    child: Child,
    stdin: Option<ChildStdin>,
    stderr: Option<JoinHandle<Vec<u8>>>,
}

impl VideoWriter {
    /// `Ok(None)` when no `ffmpeg` is on the `PATH`; the caller should say
    /// once that no video will be written.
    pub fn start(
        path: impl AsRef<Path>,
        width: u32,
        height: u32,
        fps: u32,
    ) -> Result<Option<VideoWriter>, RenderError> {
        let path = path.as_ref().to_path_buf();
        if width == 0 || height == 0 || fps == 0 {
            return Err(RenderError::Ffmpeg {
                path,
                message: format!("cannot encode {width}x{height} at {fps} fps"),
            });
        }
        let mut command = Command::new("ffmpeg");
        command.args(["-hide_banner", "-loglevel", "error", "-nostats", "-y"]);
        command.args(["-f", "rawvideo", "-pix_fmt", "rgba"]);
        command.args(["-s", &format!("{width}x{height}"), "-r", &fps.to_string()]);
        command.args(["-i", "-"]);
        if width % 2 != 0 || height % 2 != 0 {
            let [r, g, b, _] = BACKGROUND;
            command.args([
                "-vf",
                &format!("pad=ceil(iw/2)*2:ceil(ih/2)*2:0:0:color=0x{r:02x}{g:02x}{b:02x}"),
            ]);
        }
        command.args([
            "-c:v", "libx264", "-preset", "veryfast", "-pix_fmt", "yuv420p",
        ]);
        command.arg(&path);
        command
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());

        let mut child = match command.spawn() {
            Ok(child) => child,
            Err(e) if e.kind() == ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(RenderError::Io {
                    what: "starting ffmpeg for",
                    path,
                    source,
                });
            }
        };
        let stdin = child.stdin.take();
        // Drained on a thread: a child blocked on a full stderr pipe would
        // stop reading stdin and deadlock `push`.
        let stderr = child.stderr.take().map(|mut pipe| {
            std::thread::spawn(move || {
                let mut all = Vec::new();
                let _ = pipe.read_to_end(&mut all);
                let cut = all.len().saturating_sub(STDERR_TAIL);
                all.split_off(cut)
            })
        });
        Ok(Some(VideoWriter {
            path,
            width,
            height,
            child,
            stdin,
            stderr,
        }))
    }

    pub fn push(&mut self, image: &Image) -> Result<(), RenderError> {
        if (image.width, image.height) != (self.width, self.height) {
            return Err(RenderError::FrameSize {
                width: self.width,
                height: self.height,
                got_width: image.width,
                got_height: image.height,
            });
        }
        let Some(stdin) = self.stdin.as_mut() else {
            return Err(self.failure("push after finish".into()));
        };
        if let Err(e) = stdin.write_all(&image.rgba) {
            // A broken pipe means ffmpeg died; its stderr says why.
            self.stdin = None;
            let _ = self.child.wait();
            let tail = self.stderr_tail();
            return Err(self.failure(format!("writing a frame: {e}; ffmpeg said: {tail}")));
        }
        Ok(())
    }

    /// Closes ffmpeg's input, waits for it to write the file, and checks its
    /// exit status.
    pub fn finish(mut self) -> Result<(), RenderError> {
        self.stdin = None;
        let status = self.child.wait().map_err(|source| RenderError::Io {
            what: "waiting for ffmpeg writing",
            path: self.path.clone(),
            source,
        })?;
        let tail = self.stderr_tail();
        if status.success() {
            Ok(())
        } else {
            Err(self.failure(format!("exited with {status}: {tail}")))
        }
    }

    fn stderr_tail(&mut self) -> String {
        let bytes = self
            .stderr
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default();
        String::from_utf8_lossy(&bytes).trim().to_string()
    }

    fn failure(&self, message: String) -> RenderError {
        RenderError::Ffmpeg {
            path: self.path.clone(),
            message,
        }
    }
}

impl Drop for VideoWriter {
    /// A writer dropped without `finish` (an error elsewhere) still lets
    /// ffmpeg close the file and is reaped, so no zombie outlives the run.
    fn drop(&mut self) {
        self.stdin = None;
        let _ = self.child.wait();
    }
}

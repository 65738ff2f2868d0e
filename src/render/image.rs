use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::Path;

use super::RenderError;

/// An RGBA8 frame, rows top to bottom, tightly packed (`width * 4` bytes a
/// row, no GPU padding).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
}

impl Image {
    /// The pixel at column `x`, row `y` (row 0 at the top).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside {}x{}",
            self.width,
            self.height
        );
        let i = (y as usize * self.width as usize + x as usize) * 4;
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }
}

/// Keyword of the tEXt chunk a frame's PNG carries its mark under (see
/// `Frame::mark` in `frame.rs`).
pub const FRAME_MARK_KEY: &str = "rigidsim-frame";

pub fn write_png(path: impl AsRef<Path>, image: &Image) -> Result<(), RenderError> {
    write_png_marked(path, image, None)
}

/// [`write_png`] with a `FRAME_MARK_KEY` text chunk holding `mark`.
pub fn write_png_marked(
    path: impl AsRef<Path>,
    image: &Image,
    mark: Option<&str>,
) -> Result<(), RenderError> {
    let path = path.as_ref();
    let file = File::create(path).map_err(|source| RenderError::Io {
        what: "creating PNG",
        path: path.to_path_buf(),
        source,
    })?;
    let png_err = |source| RenderError::Png {
        path: path.to_path_buf(),
        source,
    };
    let mut encoder = png::Encoder::new(BufWriter::new(file), image.width, image.height);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    // The render rank writes one PNG per screen update: `Fast` took 8.7 ms
    // for a busy 1280x720 frame against 24 ms for the default `Balanced`,
    // for files 1.7x larger (166 KB against 96 KB).
    encoder.set_compression(png::Compression::Fast);
    if let Some(mark) = mark {
        encoder
            .add_text_chunk(FRAME_MARK_KEY.into(), mark.into())
            .map_err(png_err)?;
    }
    let mut writer = encoder.write_header().map_err(png_err)?;
    writer.write_image_data(&image.rgba).map_err(png_err)?;
    writer.finish().map_err(png_err)
}

/// Reads back a frame written by [`write_png`]: 8-bit RGBA, any size (the
/// caller checks it). A resumed run uses it to put the frames of the run it
/// continues at the head of its video. The `png` crate's default limits
/// (64 MiB of decoded image) refuse a damaged header before allocating.
pub fn read_png(path: impl AsRef<Path>) -> Result<Image, RenderError> {
    read_png_marked(path).map(|(image, _)| image)
}

/// [`read_png`], with the `FRAME_MARK_KEY` text the file carries, if any.
pub fn read_png_marked(path: impl AsRef<Path>) -> Result<(Image, Option<String>), RenderError> {
    let path = path.as_ref();
    let file = File::open(path).map_err(|source| RenderError::Io {
        what: "opening PNG",
        path: path.to_path_buf(),
        source,
    })?;
    let bad = |reason: String| RenderError::PngRead {
        path: path.to_path_buf(),
        reason,
    };
    let mut reader = png::Decoder::new(BufReader::new(file))
        .read_info()
        .map_err(|e| bad(e.to_string()))?;
    let mark = reader
        .info()
        .uncompressed_latin1_text
        .iter()
        .find(|t| t.keyword == FRAME_MARK_KEY)
        .map(|t| t.text.clone());
    let (color, depth) = reader.output_color_type();
    if (color, depth) != (png::ColorType::Rgba, png::BitDepth::Eight) {
        return Err(bad(format!("{color:?} {depth:?}, not 8-bit RGBA")));
    }
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| bad("image too large".into()))?;
    let mut rgba = vec![0; size];
    let info = reader
        .next_frame(&mut rgba)
        .map_err(|e| bad(e.to_string()))?;
    rgba.truncate(info.buffer_size());
    let image = Image {
        width: info.width,
        height: info.height,
        rgba,
    };
    Ok((image, mark))
}

//! `trajectory.csv`: one row per body per sample, world frame, SI units.
//! Header: `time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz`. Position is the
//! centre of mass. Numbers are written in Rust's shortest round-trip form, so
//! reading them back gives the exact simulated bits.

use super::{FNV_OFFSET, fnv1a};
use crate::body::{Body, ObjectDef};
use serde::{Deserialize, Serialize};
use std::io::{BufWriter, Read, Write};
use std::path::Path;

pub const HEADER: &str = "time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz";

pub struct TrajectoryWriter {
    out: BufWriter<std::fs::File>,
    last_time: Option<f64>,
    /// Bytes written so far and their FNV-1a 64, for checkpoints.
    mark: TrajectoryMark,
}

/// A prefix of `trajectory.csv`: its length and the FNV-1a 64 of its bytes.
/// A checkpoint keeps the mark of the file when it was written, so that a
/// resumed run appends only to the file of the run it continues, not to one
/// left in the folder by another run (or cut short, or edited).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TrajectoryMark {
    pub bytes: u64,
    pub fnv: u64,
}

impl TrajectoryMark {
    fn start() -> Self {
        TrajectoryMark {
            bytes: 0,
            fnv: FNV_OFFSET,
        }
    }

    fn add(&mut self, bytes: &[u8]) {
        self.bytes += bytes.len() as u64;
        fnv1a(&mut self.fnv, bytes);
    }
}

/// The rows a resumed run found in `trajectory.csv`.
#[derive(Debug, PartialEq, Eq)]
pub enum Continued {
    /// The file was missing: a new one was started.
    New,
    /// The file began with the checkpoint's bytes; what followed was cut.
    Kept,
}

impl TrajectoryWriter {
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let out = BufWriter::new(std::fs::File::create(path)?);
        let mut writer = TrajectoryWriter {
            out,
            last_time: None,
            mark: TrajectoryMark::start(),
        };
        writer.write(format!("{HEADER}\n").as_bytes())?;
        Ok(writer)
    }

    /// Continues the trajectory of a run resumed from a checkpoint whose
    /// trajectory was `mark`, written at `time`: checks that the file begins
    /// with exactly those bytes, drops what follows (rows a stopped run wrote
    /// after its last checkpoint, a torn last line), and appends from there.
    /// A missing file is started afresh (the caller then writes the row at
    /// `time`). A file that does not begin with the mark's bytes (another
    /// run's, shorter, edited) is an error of kind `InvalidData`, and is left
    /// as it is.
    pub fn resume(
        path: &Path,
        mark: TrajectoryMark,
        time: f64,
    ) -> std::io::Result<(Self, Continued)> {
        let Ok(file) = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
        else {
            return Ok((Self::create(path)?, Continued::New));
        };
        check_prefix(&file, mark)?;
        file.set_len(mark.bytes)?;
        let mut file = file;
        use std::io::{Seek, SeekFrom};
        file.seek(SeekFrom::Start(mark.bytes))?;
        Ok((
            TrajectoryWriter {
                out: BufWriter::new(file),
                last_time: Some(time),
                mark,
            },
            Continued::Kept,
        ))
    }

    /// What the file holds once flushed.
    pub fn mark(&self) -> TrajectoryMark {
        self.mark
    }

    fn write(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.out.write_all(bytes)?;
        self.mark.add(bytes);
        Ok(())
    }

    /// Writes every body's row at `time` (once per time). Rows are written
    /// whole, so a run that stops leaves only complete lines after `flush`.
    pub fn sample(
        &mut self,
        time: f64,
        bodies: &[Body],
        objects: &[ObjectDef],
    ) -> std::io::Result<()> {
        if self.last_time == Some(time) {
            return Ok(());
        }
        self.last_time = Some(time);
        let mut line = String::with_capacity(256);
        for (i, b) in bodies.iter().enumerate() {
            let o = &objects[b.object.0 as usize];
            let (p, q, v, w) = (
                b.state.position,
                b.state.orientation,
                b.state.velocity,
                b.angular_velocity(o),
            );
            line.clear();
            use std::fmt::Write as _;
            let _ = write!(
                line,
                "{time},{i},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                p.x, p.y, p.z, q.w, q.i, q.j, q.k, v.x, v.y, v.z, w.x, w.y, w.z
            );
            // Row and newline in one write: a run stopped mid-buffer never
            // leaves a row without its end of line.
            line.push('\n');
            self.write(line.as_bytes())?;
        }
        Ok(())
    }

    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Whether `trajectory.csv` at `path` begins with the bytes of `mark`: what
/// `--resume` checks before any rank starts work. A missing file passes (the
/// resumed run starts a new one).
pub fn check_resumable(path: &Path, mark: TrajectoryMark) -> std::io::Result<()> {
    match std::fs::File::open(path) {
        Ok(file) => check_prefix(&file, mark),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e),
    }
}

fn check_prefix(file: &std::fs::File, mark: TrajectoryMark) -> std::io::Result<()> {
    let mut found = TrajectoryMark::start();
    let mut reader = std::io::BufReader::new(file).take(mark.bytes);
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = reader.read(&mut buf)?;
        if n == 0 {
            break;
        }
        found.add(&buf[..n]);
    }
    if found != mark {
        let why = if found.bytes < mark.bytes {
            format!(
                "is shorter ({} bytes) than when the checkpoint was written ({} bytes)",
                found.bytes, mark.bytes
            )
        } else {
            format!(
                "is not the file the checkpoint's run wrote (its first {} bytes differ)",
                mark.bytes
            )
        };
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{why}; move it away or resume into another --out folder"),
        ));
    }
    Ok(())
}

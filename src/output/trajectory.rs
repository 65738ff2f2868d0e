//! `trajectory.csv`: one row per body per sample, world frame, SI units.
//! Header: `time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz`. Position is the
//! centre of mass. Numbers are written in Rust's shortest round-trip form, so
//! reading them back gives the exact simulated bits.

use crate::body::{Body, ObjectDef};
use std::io::{BufWriter, Write};
use std::path::Path;

pub const HEADER: &str = "time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz";

pub struct TrajectoryWriter {
    out: BufWriter<std::fs::File>,
    last_time: Option<f64>,
}

impl TrajectoryWriter {
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let mut out = BufWriter::new(std::fs::File::create(path)?);
        writeln!(out, "{HEADER}")?;
        Ok(TrajectoryWriter {
            out,
            last_time: None,
        })
    }

    /// Continues the trajectory of a run resumed from a checkpoint taken at
    /// `time`: keeps the header and the complete rows up to and including
    /// `time`, drops what follows (rows a stopped run wrote after its last
    /// checkpoint, a torn last line), and appends from there. A missing file,
    /// or one with another header, is started afresh. Returns the writer and
    /// the number of data rows kept (0: the caller writes the row at `time`).
    pub fn resume(path: &Path, time: f64) -> std::io::Result<(Self, usize)> {
        use std::io::{BufRead, BufReader, Seek, SeekFrom};
        let Ok(file) = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
        else {
            return Ok((Self::create(path)?, 0));
        };
        let mut reader = BufReader::new(&file);
        let mut line = Vec::new();
        reader.read_until(b'\n', &mut line)?;
        if line != format!("{HEADER}\n").as_bytes() {
            drop(reader);
            return Ok((Self::create(path)?, 0));
        }
        let mut keep = line.len() as u64;
        let mut rows = 0usize;
        let mut last_time = None;
        loop {
            line.clear();
            let n = reader.read_until(b'\n', &mut line)?;
            if n == 0 || line.last() != Some(&b'\n') {
                break;
            }
            let t = line
                .split(|&c| c == b',')
                .next()
                .and_then(|f| std::str::from_utf8(f).ok())
                .and_then(|f| f.parse::<f64>().ok());
            match t {
                Some(t) if t <= time => {
                    keep += n as u64;
                    rows += 1;
                    last_time = Some(t);
                }
                _ => break,
            }
        }
        drop(reader);
        file.set_len(keep)?;
        let mut file = file;
        file.seek(SeekFrom::Start(keep))?;
        Ok((
            TrajectoryWriter {
                out: BufWriter::new(file),
                last_time,
            },
            rows,
        ))
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
            self.out.write_all(line.as_bytes())?;
        }
        Ok(())
    }

    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

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
            writeln!(self.out, "{line}")?;
        }
        Ok(())
    }

    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

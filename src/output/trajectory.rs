//! `trajectory.csv`: one row per body per sample, world frame, SI units.
//! Header: `time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz`. Position is the
//! centre of mass. Numbers are written in Rust's shortest round-trip form, so
//! reading them back gives the exact simulated bits.

use super::{FNV_OFFSET, decimal, fnv1a};
use crate::body::{Body, ObjectDef};
use serde::{Deserialize, Serialize};
use std::io::{BufWriter, Read, Write};
use std::path::Path;
use std::sync::{Arc, Mutex, mpsc};

pub const HEADER: &str = "time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz";

/// Writes `trajectory.csv` on a thread of its own: `sample` copies the
/// bodies' numbers and hands them over, and the thread formats and writes
/// them (formatting every body's 13 numbers each step was 4 % of rank 0's
/// time on the 200-body pour, all of it on the critical path of a
/// distributed step while the workers wait). The file's bytes are exactly
/// those of writing in place; `flush` waits for every row handed over.
pub struct TrajectoryWriter {
    /// Rows to the writer thread (bounded: a slow disk holds the run back
    /// rather than fill the memory); None once closed.
    rows: Option<mpsc::SyncSender<Job>>,
    /// The thread's answer to each `Job::Flush`: the mark of the file
    /// flushed, or the first write error.
    flushed: mpsc::Receiver<std::io::Result<TrajectoryMark>>,
    /// The first write error, as soon as the thread meets it (`sample`
    /// returns it).
    failed: Arc<Mutex<Option<std::io::Error>>>,
    thread: Option<std::thread::JoinHandle<()>>,
    last_time: Option<f64>,
    /// What the file held at the last `flush`.
    mark: TrajectoryMark,
    /// Whether the mark's hash is kept (`Marking`).
    marking: Marking,
}

/// Whether a writer hashes what it writes, for the checkpoints' marks.
/// FNV-1a goes byte by byte, a quarter of the writer thread's time (10 MB
/// for the 200-body pour's 2 s), and the thread shares the cores with the
/// ranks: a run that writes no checkpoint counts the bytes only.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Marking {
    /// Bytes and hash: `mark` answers.
    Hashed,
    /// Bytes only: `mark` must not be asked.
    Counted,
}

/// Work for the writer thread.
enum Job {
    /// One sample: its time and each body's position, orientation (w, i,
    /// j, k), velocity and angular velocity.
    Rows(f64, Vec<[f64; 13]>),
    Flush,
}

/// Samples the writer thread may hold before `sample` waits for it.
const SAMPLES_IN_FLIGHT: usize = 64;

/// Bytes the writer gathers before each write to the file: large enough
/// that a run's rows take a few system calls, not one per 8 KiB (std's).
const WRITE_BUFFER: usize = 1 << 20;

/// The writer thread's side: the file and what it holds.
struct RowWriter {
    out: BufWriter<std::fs::File>,
    mark: TrajectoryMark,
    marking: Marking,
}

impl RowWriter {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.out.write_all(bytes)?;
        match self.marking {
            Marking::Hashed => self.mark.add(bytes),
            Marking::Counted => self.mark.bytes += bytes.len() as u64,
        }
        Ok(())
    }

    fn rows(&mut self, time: f64, rows: &[[f64; 13]]) -> std::io::Result<()> {
        let mut line: Vec<u8> = Vec::with_capacity(320);
        let mut digits = zmij::Buffer::new();
        let mut index = itoa::Buffer::new();
        let mut when = Vec::new();
        decimal::push_f64(&mut when, &mut digits, time);
        for (i, r) in rows.iter().enumerate() {
            // `{time},{i},{x},…` with std's `Display` bytes.
            line.clear();
            line.extend_from_slice(&when);
            line.push(b',');
            line.extend_from_slice(index.format(i).as_bytes());
            for &v in r {
                line.push(b',');
                decimal::push_f64(&mut line, &mut digits, v);
            }
            // Row and newline in one write: a run stopped mid-buffer never
            // leaves a row without its end of line.
            line.push(b'\n');
            self.write(&line)?;
        }
        Ok(())
    }

    /// Serves jobs until the writer is dropped. After a write error it
    /// writes nothing more and answers every flush with that error.
    fn serve(
        mut self,
        jobs: mpsc::Receiver<Job>,
        flushed: mpsc::SyncSender<std::io::Result<TrajectoryMark>>,
        failed: Arc<Mutex<Option<std::io::Error>>>,
    ) {
        // The first error, kept to answer every later flush with.
        let mut error: Option<(std::io::ErrorKind, String)> = None;
        let again = |e: &(std::io::ErrorKind, String)| std::io::Error::new(e.0, e.1.clone());
        for job in jobs {
            match job {
                Job::Rows(time, rows) => {
                    if error.is_none() {
                        if let Err(e) = self.rows(time, &rows) {
                            error = Some((e.kind(), e.to_string()));
                            *failed.lock().unwrap() = Some(e);
                        }
                    }
                }
                Job::Flush => {
                    if error.is_none() {
                        if let Err(e) = self.out.flush() {
                            error = Some((e.kind(), e.to_string()));
                        }
                    }
                    let _ = flushed.send(match &error {
                        Some(e) => Err(again(e)),
                        None => Ok(self.mark),
                    });
                }
            }
        }
        // Dropped: the BufWriter flushes what it holds.
    }
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
    pub fn create(path: &Path, marking: Marking) -> std::io::Result<Self> {
        let mut out = RowWriter {
            out: BufWriter::with_capacity(WRITE_BUFFER, std::fs::File::create(path)?),
            mark: TrajectoryMark::start(),
            marking,
        };
        out.write(format!("{HEADER}\n").as_bytes())?;
        Ok(Self::start(out, None))
    }

    /// Hands `out` to a writer thread.
    fn start(out: RowWriter, last_time: Option<f64>) -> Self {
        let (rows, jobs) = mpsc::sync_channel(SAMPLES_IN_FLIGHT);
        let (flushed_tx, flushed) = mpsc::sync_channel(1);
        let failed = Arc::new(Mutex::new(None));
        let (mark, marking) = (out.mark, out.marking);
        let shared = Arc::clone(&failed);
        let thread = std::thread::Builder::new()
            .name("trajectory".into())
            .spawn(move || {
                free_of_the_rank_binding();
                out.serve(jobs, flushed_tx, shared)
            })
            .expect("spawn the trajectory writer thread");
        TrajectoryWriter {
            rows: Some(rows),
            flushed,
            failed,
            thread: Some(thread),
            last_time,
            mark,
            marking,
        }
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
        marking: Marking,
    ) -> std::io::Result<(Self, Continued)> {
        let Ok(file) = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
        else {
            return Ok((Self::create(path, marking)?, Continued::New));
        };
        check_prefix(&file, mark)?;
        file.set_len(mark.bytes)?;
        let mut file = file;
        use std::io::{Seek, SeekFrom};
        file.seek(SeekFrom::Start(mark.bytes))?;
        let out = RowWriter {
            out: BufWriter::with_capacity(WRITE_BUFFER, file),
            mark,
            marking,
        };
        Ok((Self::start(out, Some(time)), Continued::Kept))
    }

    /// What the file held at the last `flush` (a checkpoint flushes
    /// first), for a writer made with `Marking::Hashed`.
    pub fn mark(&self) -> TrajectoryMark {
        assert_eq!(
            self.marking,
            Marking::Hashed,
            "a checkpoint's mark from a writer that counts bytes only"
        );
        self.mark
    }

    /// What the file at `path` held at the last `flush`, as `mark` gives
    /// it, also for a writer made with `Marking::Counted`: its hash is then
    /// read back from the file. For the checkpoint of a run interrupted
    /// without `--checkpoint-every` (`crate::interrupt`), once, at its end.
    pub fn mark_read_back(&self, path: &Path) -> std::io::Result<TrajectoryMark> {
        if self.marking == Marking::Hashed {
            return Ok(self.mark);
        }
        let found = mark_of_prefix(&std::fs::File::open(path)?, self.mark.bytes)?;
        if found.bytes != self.mark.bytes {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "holds {} bytes, {} were written",
                    found.bytes, self.mark.bytes
                ),
            ));
        }
        Ok(found)
    }

    /// The first write error the thread met, if any.
    fn check(&self) -> std::io::Result<()> {
        match self.failed.lock().unwrap().take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    fn send(&self, job: Job) -> std::io::Result<()> {
        self.rows
            .as_ref()
            .ok_or_else(stopped)?
            .send(job)
            .map_err(|_| stopped())
    }

    /// Writes every body's row at `time` (once per time). Rows are written
    /// whole, so a run that stops leaves only complete lines after `flush`.
    pub fn sample(
        &mut self,
        time: f64,
        bodies: &[Body],
        objects: &[ObjectDef],
    ) -> std::io::Result<()> {
        self.check()?;
        if self.last_time == Some(time) {
            return Ok(());
        }
        self.last_time = Some(time);
        let rows = bodies
            .iter()
            .map(|b| {
                let o = &objects[b.object.0 as usize];
                let (p, q, v, w) = (
                    b.state.position,
                    b.state.orientation,
                    b.state.velocity,
                    b.angular_velocity(o),
                );
                [
                    p.x, p.y, p.z, q.w, q.i, q.j, q.k, v.x, v.y, v.z, w.x, w.y, w.z,
                ]
            })
            .collect();
        self.send(Job::Rows(time, rows))
    }

    /// Waits until every row handed over is written and the file flushed
    /// (or answers the first write error: the thread takes jobs in order).
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.send(Job::Flush)?;
        self.mark = self.flushed.recv().map_err(|_| stopped())??;
        Ok(())
    }
}

/// The error for a writer thread that is gone.
fn stopped() -> std::io::Error {
    std::io::Error::other("the trajectory writer thread stopped")
}

impl Drop for TrajectoryWriter {
    /// Closes the thread's queue and waits for it to write what it holds.
    fn drop(&mut self) {
        self.rows = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
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

/// The mark of the first `bytes` bytes of `file` (fewer if it is shorter).
fn mark_of_prefix(file: &std::fs::File, bytes: u64) -> std::io::Result<TrajectoryMark> {
    let mut found = TrajectoryMark::start();
    let mut reader = std::io::BufReader::new(file).take(bytes);
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = reader.read(&mut buf)?;
        if n == 0 {
            break;
        }
        found.add(&buf[..n]);
    }
    Ok(found)
}

fn check_prefix(file: &std::fs::File, mark: TrajectoryMark) -> std::io::Result<()> {
    let found = mark_of_prefix(file, mark.bytes)?;
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

/// Lets the calling thread run on any online core. `mpirun` binds each rank
/// to one core (Open MPI binds to cores for up to two processes), and a
/// thread inherits its process's binding: the writer thread then took its
/// turns on rank 0's own core, in the middle of the step it was meant to
/// stay out of. Unbound, it runs wherever a core is free. Best effort: on
/// failure the thread keeps the binding it had.
#[cfg(target_os = "linux")]
fn free_of_the_rank_binding() {
    // SAFETY: sysconf, and CPU_SET / sched_setaffinity on a zeroed
    // cpu_set_t owned by this frame, for this thread (pid 0).
    unsafe {
        let online = libc::sysconf(libc::_SC_NPROCESSORS_ONLN);
        if online <= 0 {
            return;
        }
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for cpu in 0..(online as usize).min(libc::CPU_SETSIZE as usize) {
            libc::CPU_SET(cpu, &mut set);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
    }
}

#[cfg(not(target_os = "linux"))]
fn free_of_the_rank_binding() {}

//! Rank 0's messages to its workers: sends (blocking and posted), replies,
//! and the deadline that ends the job when a worker stops answering.

use super::MpiExecutor;
use super::protocol::{self, Reply, Request as Req, decode, encode};
use mpi::point_to_point::{Destination, Source};
use mpi::request::{Request, StaticScope};
use mpi::topology::Communicator;
use std::time::{Duration, Instant};

/// Spins briefly, then yields: past the first thousand polls the coordinator
/// stops burning a core it may share with workers on small clusters.
pub(super) fn pause(spins: u32) {
    if spins > 1000 {
        std::thread::sleep(Duration::from_micros(50));
    } else {
        std::hint::spin_loop();
    }
}

/// A worker silent for this long is taken as lost (a stage's share is
/// planned to take milliseconds; even a slowed PC answers within seconds).
const REPLY_DEADLINE: Duration = Duration::from_secs(10);

/// A request on its way to a worker, sent without blocking: MPI reads the
/// buffer until the send completes, so it is freed only then (`reap_posts`).
pub(super) struct Posted {
    request: Request<'static, [u8], StaticScope>,
    buffer: *mut [u8],
    rank: i32,
    since: Instant,
}

impl MpiExecutor<'_> {
    fn slot_of(&self, rank: i32) -> usize {
        self.roles
            .workers
            .iter()
            .position(|&w| w == rank)
            .map_or(0, |p| p + 1)
    }

    pub(super) fn send(&mut self, rank: i32, req: &Req) {
        let bytes = encode(req);
        let slot = self.slot_of(rank);
        self.book[slot].bytes_sent += bytes.len() as u64;
        // Non-blocking, polled against the deadline: a large request waits for
        // the receiver to post its receive, and a stopped rank never will.
        let process = self.world.process_at_rank(rank);
        let start = Instant::now();
        mpi::request::scope(|scope| {
            let mut request =
                process.immediate_send_with_tag(scope, &bytes[..], protocol::TAG_REQUEST);
            let mut spins = 0u32;
            loop {
                match request.test() {
                    Ok(_) => break,
                    Err(pending) => request = pending,
                }
                if start.elapsed() > REPLY_DEADLINE {
                    self.lost(rank);
                }
                spins += 1;
                pause(spins);
            }
        });
    }

    /// Ends the whole job: `rank` stopped answering.
    fn lost(&self, rank: i32) -> ! {
        eprintln!(
            "rigidsim: rank 0: rank {rank} ({}, on host {}) has not answered for {} s; ending the run",
            self.roles.role_of(rank),
            self.host_of(rank),
            REPLY_DEADLINE.as_secs()
        );
        self.world.abort(5)
    }

    pub(super) fn receive(&mut self, rank: i32) -> Reply {
        self.await_reply(rank);
        let (bytes, _) = self
            .world
            .process_at_rank(rank)
            .receive_vec_with_tag::<u8>(protocol::TAG_REPLY);
        let slot = self.slot_of(rank);
        self.book[slot].bytes_received += bytes.len() as u64;
        decode(&bytes).unwrap_or_else(|e| {
            eprintln!("rigidsim: rank 0: bad reply from rank {rank}: {e}");
            self.world.abort(4)
        })
    }

    /// Waits for `rank`'s reply without blocking inside MPI, so a rank that
    /// stops answering (hung, stopped, or its PC frozen) ends the run with a
    /// message naming it instead of a silent hang. A rank that dies outright
    /// is caught by mpirun, which ends the job and names the process.
    fn await_reply(&self, rank: i32) {
        let start = Instant::now();
        let process = self.world.process_at_rank(rank);
        let mut spins = 0u32;
        while process
            .immediate_probe_with_tag(protocol::TAG_REPLY)
            .is_none()
        {
            if start.elapsed() > REPLY_DEADLINE {
                self.lost(rank);
            }
            spins += 1;
            pause(spins);
        }
    }

    /// Sends `req` to `rank` without waiting for it to be received.
    pub(super) fn post(&mut self, rank: i32, req: &Req, posted: &mut Vec<Posted>) {
        let bytes = encode(req).into_boxed_slice();
        let slot = self.slot_of(rank);
        self.book[slot].bytes_sent += bytes.len() as u64;
        let buffer: *mut [u8] = Box::into_raw(bytes);
        // SAFETY: `buffer` stays allocated until the request completes
        // (`reap_posts` frees it then, and only then).
        let data: &'static [u8] = unsafe { &*buffer };
        let request = self.world.process_at_rank(rank).immediate_send_with_tag(
            StaticScope,
            data,
            protocol::TAG_REQUEST,
        );
        posted.push(Posted {
            request,
            buffer,
            rank,
            since: Instant::now(),
        });
    }

    /// Completes the sends that are done and frees their buffers; with
    /// `all`, waits for every one (a worker that never takes its request is
    /// lost, as in `send`).
    pub(super) fn reap_posts(&self, posted: &mut Vec<Posted>, all: bool) {
        let mut spins = 0u32;
        loop {
            let mut still = Vec::new();
            for p in posted.drain(..) {
                match p.request.test() {
                    // SAFETY: leaked from a Box in `post`; MPI is done with it.
                    Ok(_) => drop(unsafe { Box::from_raw(p.buffer) }),
                    Err(request) => {
                        if p.since.elapsed() > REPLY_DEADLINE {
                            self.lost(p.rank);
                        }
                        still.push(Posted { request, ..p });
                    }
                }
            }
            *posted = still;
            if !all || posted.is_empty() {
                return;
            }
            spins += 1;
            pause(spins);
        }
    }
}

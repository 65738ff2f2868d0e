//! Everything MPI (SPEC 3): rank roles, the coordinator's executor that
//! scatters exact collision and Dantzig solves over workers, the worker loop,
//! and the render rank.
//!
//! Roles: rank 0 coordinates (and does its own, smaller share); ranks 1 … N−2
//! are workers; the last rank renders when the scene has a `[render]` section
//! and `--no-render` is not given, otherwise it is a worker too. One rank runs
//! the same stages inline.

pub mod protocol;
pub mod schedule;

use crate::body::ObjectDef;
use crate::collision::narrowphase::{self, PairResult, PairTask};
use crate::contact::solver::{self, IslandResult, IslandTask};
use crate::output::summary::{Distribution, RankSummary};
use crate::run::{Frame, FrameRenderer, FrameSink};
use crate::scene::{ForceWindow, Scene};
use crate::step::stats::StageClock;
use crate::step::{
    Executor, GroupInput, GroupParams, GroupReply, Inline, PreparedPairs, SPLIT_AUTO_MIN_MEMBERS,
    SPLIT_MIN_MEMBERS, StepStatic, prepare_pairs, run_group,
};
use mpi::point_to_point::{Destination, Source};
use mpi::request::{Request, StaticScope};
use mpi::topology::{Communicator, SimpleCommunicator};
use protocol::{RenderMessage, RenderReport, Reply, Request as Req, WorkerReport, decode, encode};
use schedule::CostModel;
use std::collections::{BTreeMap, VecDeque};
use std::path::Path;
use std::time::{Duration, Instant};

#[derive(Clone, Debug, PartialEq)]
pub struct Roles {
    pub size: i32,
    pub workers: Vec<i32>,
    pub renderer: Option<i32>,
}

impl Roles {
    pub fn new(size: i32, render: bool) -> Roles {
        let renderer = (render && size >= 2).then_some(size - 1);
        let last_worker = if renderer.is_some() {
            size - 2
        } else {
            size - 1
        };
        Roles {
            size,
            workers: (1..=last_worker).collect(),
            renderer,
        }
    }

    pub fn role_of(&self, rank: i32) -> &'static str {
        if rank == 0 {
            "coordinator"
        } else if Some(rank) == self.renderer {
            "renderer"
        } else {
            "worker"
        }
    }
}

/// Test aid: `--slow-rank R=F` makes rank R take F times longer per batch
/// (it spins for (F − 1)× its work's CPU time), like a PC another user is loading.
pub fn slow_factor(slow: &[(i32, f64)], rank: i32) -> f64 {
    slow.iter()
        .filter(|(r, _)| *r == rank)
        .map(|(_, f)| *f)
        .fold(1.0, f64::max)
}

/// CPU time this thread has used. A slowed rank's extra work is counted in
/// it, not on the wall clock: on a loaded machine a batch's wall time
/// includes time the rank sat preempted, and stalling (factor − 1)× that
/// multiplied every preemption spike (a rank set 3× slower measured 21×
/// slower while another job used the second core).
fn thread_cpu_time() -> Duration {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_THREAD_CPUTIME_ID
    // is supported on every Linux the cluster runs on.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return Duration::ZERO;
    }
    Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

/// Keeps the CPU busy for (factor − 1)× the CPU time the batch's work took
/// (`cpu_at_start` was read when it began), as a slower PC would, and
/// returns the batch's wall time `since` it began. A sleep would not do: its
/// granularity (tens of µs) dwarfs the microsecond batches of small scenes
/// and would fake a much slower rank.
fn stall(factor: f64, since: Instant, cpu_at_start: Duration) -> Duration {
    if factor > 1.0 {
        let now = thread_cpu_time();
        let until = now + now.saturating_sub(cpu_at_start).mul_f64(factor - 1.0);
        while thread_cpu_time() < until {
            std::hint::spin_loop();
        }
    }
    since.elapsed()
}

/// Smoothed moments of (cost given, busy time reported) per batch, for a
/// least-squares fit busy = overhead + cost / speed. The fixed per-batch
/// overhead would otherwise make a rank given only small tasks look slow, get
/// even smaller tasks, and starve.
#[derive(Default, Clone)]
struct SpeedMeter {
    c: f64,
    b: f64,
    cc: f64,
    cb: f64,
}

impl SpeedMeter {
    fn add(&mut self, cost: f64, busy: f64) {
        let s = schedule::smooth_slow;
        self.c = s(self.c, cost);
        self.b = s(self.b, busy);
        self.cc = s(self.cc, cost * cost);
        self.cb = s(self.cb, cost * busy);
    }

    /// 1 / slope of the fit, kept within 4× of plain cost / busy (which
    /// overhead biases low, but noise cannot swing): a fit over microsecond
    /// batches on shared cores can otherwise run away.
    fn speed(&self) -> f64 {
        let ratio = self.c / self.b;
        let var = self.cc - self.c * self.c;
        let cov = self.cb - self.c * self.b;
        if var > 0.01 * self.cc && cov > 0.0 {
            (var / cov).clamp(ratio, 4.0 * ratio)
        } else {
            ratio
        }
    }
}

#[derive(Default, Clone)]
struct RankBook {
    tasks_np: u64,
    tasks_is: u64,
    cost_s: f64,
    busy_s: f64,
    waiting_s: f64,
    bytes_sent: u64,
    bytes_received: u64,
}

/// Spins briefly, then yields: past the first thousand polls the coordinator
/// stops burning a core it may share with workers on small clusters.
fn pause(spins: u32) {
    if spins > 1000 {
        std::thread::sleep(Duration::from_micros(50));
    } else {
        std::hint::spin_loop();
    }
}

/// A worker silent for this long is taken as lost (a stage's share is
/// planned to take milliseconds; even a slowed PC answers within seconds).
const REPLY_DEADLINE: Duration = Duration::from_secs(10);

/// The render rank silent for this long after the run's last frame is
/// taken as lost. Its final work comes in pieces that each take well under
/// a second (a queued frame drawn, an earlier frame read back into the
/// video), each followed by a `TAG_RENDER_ALIVE` message; the longest
/// silence is ffmpeg finishing the video, a few seconds.
const RENDER_DEADLINE: Duration = Duration::from_secs(30);

/// Share of its speed that rank 0 plans for itself (it also packs and merges).
const COORDINATOR_SHARE: f64 = 0.5;
/// The same for the self-scheduled stages (island solves, group steps),
/// when deciding whether to distribute them: rank 0 works through tasks
/// while the workers work through theirs (`self_schedule`), so it counts at
/// full speed.
const SELF_SCHEDULED_SHARE: f64 = 1.0;
/// Chunks of group steps a worker holds at most. Two (the one it steps and
/// the next, so that it never waits for rank 0 between them) commit the
/// second chunk while little is known of the first: on the 200-body pour
/// two ranks took 2.68 s against 2.38 s with one (medians of 5, alternating).
const CHUNKS_IN_FLIGHT: usize = 1;
/// A chunk holds at least this share of the work not yet handed out, times
/// the worker's share of the speed of the ranks taking part (guided
/// self-scheduling): large chunks while much is left, few messages; small
/// ones at the end, where an estimate that was off could leave a rank
/// waiting. By speed, because a stage often ends with every worker's first
/// chunk: equal chunks gave a rank measured 3× slower as much work as the
/// others, and the stage waited for it.
const CHUNK_SHARE: f64 = 0.5;

/// How often rank 0 looks for answers while it steps a group of its own
/// (`Polled`): a probe per worker costs about a microsecond, and an event
/// calls the executor a few times.
const POLL_EVERY: Duration = Duration::from_micros(20);

/// Rank 0's executor for a group step of its own within a self-scheduled
/// stage: every stage the group calls runs inline, after serving the
/// workers (`poll`).
struct Polled<'p> {
    inline: Inline,
    poll: &'p mut dyn FnMut(),
}

impl<'p> Polled<'p> {
    fn new(poll: &'p mut dyn FnMut()) -> Self {
        Polled {
            inline: Inline::default(),
            poll,
        }
    }
}

impl Executor for Polled<'_> {
    // Task by task, polling between them: a group's first batch holds all
    // its pairs (milliseconds for a pile), and a worker waiting for its
    // next chunk would wait for all of it.
    fn narrowphase(&mut self, objects: &[ObjectDef], tasks: Vec<PairTask>) -> Vec<PairResult> {
        tasks
            .iter()
            .map(|t| {
                (self.poll)();
                narrowphase::query_pair(objects, t)
            })
            .collect()
    }
    fn solve_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        tasks
            .iter()
            .map(|t| {
                (self.poll)();
                solver::solve_island(t)
            })
            .collect()
    }
    fn step_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<GroupReply> {
        (self.poll)();
        self.inline.step_groups(st, params, inputs)
    }
    fn prepare_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<PreparedPairs> {
        (self.poll)();
        self.inline.prepare_groups(st, params, inputs)
    }
    fn poll(&mut self) {
        (self.poll)();
    }
    fn finish(&mut self) -> (Vec<RankSummary>, Distribution) {
        self.inline.finish()
    }
}

/// A request on its way to a worker, sent without blocking: MPI reads the
/// buffer until the send completes, so it is freed only then (`reap_posts`).
struct Posted {
    request: Request<'static, [u8], StaticScope>,
    buffer: *mut [u8],
    rank: i32,
    since: Instant,
}

/// The tasks of one self-scheduled stage, largest first: workers take
/// chunks from the front, rank 0 one task at a time from the back.
struct Feed {
    order: Vec<usize>,
    front: usize,
    back: usize,
    /// Estimated seconds not yet handed out.
    left_s: f64,
}

impl Feed {
    fn new(costs: &[f64]) -> Self {
        let mut order: Vec<usize> = (0..costs.len()).collect();
        order.sort_by(|&i, &j| costs[j].total_cmp(&costs[i]).then(i.cmp(&j)));
        Feed {
            front: 0,
            back: order.len(),
            order,
            left_s: costs.iter().sum(),
        }
    }

    /// The next chunk for a worker whose share of the ranks' speed is
    /// `share`: the largest tasks left, at least one, up to `CHUNK_SHARE`
    /// of that share of what is left.
    fn chunk(&mut self, costs: &[f64], share: f64) -> Option<Vec<usize>> {
        if self.front == self.back {
            return None;
        }
        let target = CHUNK_SHARE * self.left_s * share;
        let mut chunk = Vec::new();
        let mut cost = 0.0;
        while self.front < self.back
            && (chunk.is_empty() || cost + costs[self.order[self.front]] <= target)
        {
            let i = self.order[self.front];
            cost += costs[i];
            chunk.push(i);
            self.front += 1;
        }
        self.left_s -= cost;
        Some(chunk)
    }

    /// The next task for rank 0: the smallest left.
    fn own(&mut self, costs: &[f64]) -> Option<usize> {
        if self.front == self.back {
            return None;
        }
        self.back -= 1;
        let i = self.order[self.back];
        self.left_s -= costs[i];
        Some(i)
    }
}

/// Rank 0's executor: decides per stage and per frame whether to distribute;
/// pair tasks by the thesis's greedy plan (one message to each worker, its
/// own share, gather), island solves and group steps by self-scheduling
/// (chunks handed out as workers answer, rank 0 taking the smallest tasks
/// in between); results merged in task order either way.
pub struct MpiExecutor<'w> {
    world: &'w SimpleCommunicator,
    roles: Roles,
    model: CostModel,
    /// Estimated speed per slot: slot 0 is rank 0, slot k is `roles.workers[k-1]`.
    speeds: Vec<f64>,
    book: Vec<RankBook>,
    meters: Vec<SpeedMeter>,
    latency_s: f64,
    dist: Distribution,
    clock: StageClock,
    polygons: Vec<usize>,
    parts: Vec<usize>,
    /// Distribute regardless of cost (tests of determinism and balance).
    pub force_distribute: bool,
    /// Split the groups that would hold up the other ranks
    /// (`Executor::split_groups`; on unless `--whole-groups`).
    pub split_where_it_pays: bool,
    net: Network,
    /// Where the group steps and the island solves went and what they
    /// took (`StageChoice`).
    group_choice: schedule::StageChoice,
    /// Whether splitting the groups that would hold the others up pays,
    /// measured as for `group_choice` ("out" is split), and this step's
    /// choice, predicted cost and start (`Executor::groups_stepped`).
    split_choice: schedule::StageChoice,
    split_step: Option<(bool, f64, Instant)>,
    solve_choice: schedule::StageChoice,
}

impl<'w> MpiExecutor<'w> {
    pub fn new(world: &'w SimpleCommunicator, roles: Roles, objects: &[ObjectDef]) -> Self {
        let slots = roles.workers.len() + 1;
        let mut exec = MpiExecutor {
            world,
            model: CostModel::default(),
            speeds: vec![1.0; slots],
            book: vec![RankBook::default(); slots],
            meters: vec![SpeedMeter::default(); slots],
            latency_s: 0.0,
            dist: Distribution::default(),
            clock: StageClock::default(),
            polygons: objects.iter().map(|o| o.polygon_count).collect(),
            parts: objects.iter().map(|o| o.parts.len()).collect(),
            force_distribute: false,
            split_where_it_pays: true,
            net: Network::default(),
            group_choice: schedule::StageChoice::default(),
            split_choice: schedule::StageChoice::default(),
            split_step: None,
            solve_choice: schedule::StageChoice::default(),
            roles,
        };
        exec.measure_latency();
        exec.measure_link_rates();
        exec
    }

    /// Median round trip of a tiny message to each worker.
    fn measure_latency(&mut self) {
        let mut samples = Vec::new();
        for _ in 0..5 {
            for &w in &self.roles.workers.clone() {
                let t = Instant::now();
                self.send(w, &Req::Ping);
                let _ = self.receive(w);
                samples.push(t.elapsed().as_secs_f64());
            }
        }
        samples.sort_by(f64::total_cmp);
        self.latency_s = samples.get(samples.len() / 2).copied().unwrap_or(0.0);
        self.dist.message_latency_s = self.latency_s;
    }

    fn slot_of(&self, rank: i32) -> usize {
        self.roles
            .workers
            .iter()
            .position(|&w| w == rank)
            .map_or(0, |p| p + 1)
    }

    fn send(&mut self, rank: i32, req: &Req) {
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

    fn receive(&mut self, rank: i32) -> Reply {
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

    /// Workers the pair tasks of this estimated cost should use (0: rank 0
    /// alone), from the measured round trip, the link's rate and the
    /// estimated speeds; see `schedule::workers_to_use_over_link`.
    /// `--force-distribute` uses them all.
    fn workers_for(&self, estimated_s: f64, tasks: usize) -> usize {
        self.workers_for_stage(Stage::Narrowphase, estimated_s, tasks, COORDINATOR_SHARE)
    }

    /// Splits tasks by the greedy rule over rank 0 and the `k` fastest
    /// workers; returns per slot the task indices.
    fn plan(&self, costs: &[f64], k: usize, share: f64) -> Vec<Vec<usize>> {
        let used = schedule::fastest_slots(&self.speeds, k);
        let speeds: Vec<f64> = self
            .speeds
            .iter()
            .zip(&used)
            .map(|(&s, &u)| if u { s } else { 0.0 })
            .collect();
        let slot = schedule::assign(costs, &speeds, share);
        let mut per = vec![Vec::new(); self.speeds.len()];
        for (i, s) in slot.into_iter().enumerate() {
            per[s].push(i);
        }
        per
    }

    /// Generic scatter–compute–gather for one stage.
    #[allow(clippy::too_many_arguments)]
    fn distribute<T: Clone, R>(
        &mut self,
        workers: usize,
        share: f64,
        tasks: Vec<T>,
        costs: &[f64],
        make: impl Fn(Vec<T>) -> Req,
        local: impl Fn(&[T]) -> Vec<R>,
        unpack: impl Fn(Reply) -> Option<(Vec<R>, f64)>,
    ) -> (Vec<R>, f64, Vec<usize>)
    where
        R: Default + Clone,
    {
        let plan = self.plan(costs, workers, share);
        // Send each worker its share (one message each).
        for (k, idx) in plan.iter().enumerate().skip(1) {
            if idx.is_empty() {
                continue;
            }
            let rank = self.roles.workers[k - 1];
            let share: Vec<T> = idx.iter().map(|&i| tasks[i].clone()).collect();
            let cost: f64 = idx.iter().map(|&i| costs[i]).sum();
            self.book[k].cost_s += cost;
            self.send(rank, &make(share));
        }
        // Rank 0's own share.
        let own: Vec<T> = plan[0].iter().map(|&i| tasks[i].clone()).collect();
        let clock = Instant::now();
        let own_results = local(&own);
        let own_s = clock.elapsed().as_secs_f64();
        let own_cost: f64 = plan[0].iter().map(|&i| costs[i]).sum();
        self.book[0].busy_s += own_s;
        self.book[0].cost_s += own_cost;
        let mut total_busy = own_s;
        self.meter(0, own_cost, own_s);
        let mut results: Vec<R> = vec![R::default(); tasks.len()];
        for (r, &i) in own_results.into_iter().zip(&plan[0]) {
            results[i] = r;
        }
        // Gather, merging by task index (never arrival order).
        let wait = Instant::now();
        for (k, idx) in plan.iter().enumerate().skip(1) {
            if idx.is_empty() {
                continue;
            }
            let (rs, busy) = self.gather(k, idx, costs, &unpack);
            total_busy += busy;
            for (r, &i) in rs.into_iter().zip(idx) {
                results[i] = r;
            }
        }
        let waited = wait.elapsed().as_secs_f64();
        self.book[0].waiting_s += waited;
        let own = plan.into_iter().next().unwrap_or_default();
        (results, total_busy, own)
    }

    /// Sends `req` to `rank` without waiting for it to be received.
    fn post(&mut self, rank: i32, req: &Req, posted: &mut Vec<Posted>) {
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
    fn reap_posts(&self, posted: &mut Vec<Posted>, all: bool) {
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

    /// Scatter–compute–gather by self-scheduling (for group steps, whose
    /// costs are predictions from the last step and often off): the tasks
    /// sorted largest first, each worker holds up to `CHUNKS_IN_FLIGHT`
    /// chunks from the front and gets the next when it answers, and rank 0
    /// steps single tasks from the back in between, so no rank waits while
    /// work is left. Results are merged by task index, never by arrival
    /// order or by where a task ran. Returns the results and rank 0's tasks.
    fn self_schedule<T, R>(
        &mut self,
        workers: usize,
        tasks: Vec<T>,
        costs: &[f64],
        make: impl Fn(Vec<T>) -> Req,
        local: impl Fn(T, &mut dyn FnMut()) -> R,
        unpack: impl Fn(Reply) -> Option<(Vec<R>, f64)>,
    ) -> (Vec<R>, f64, Vec<usize>) {
        let used = schedule::fastest_slots(&self.speeds, workers);
        let slots: Vec<usize> = (1..self.speeds.len()).filter(|&s| used[s]).collect();
        // Each worker's share of the speed of the ranks taking part.
        let total_speed = self.speeds[0] * SELF_SCHEDULED_SHARE
            + slots.iter().map(|&s| self.speeds[s]).sum::<f64>();
        let speed_share: Vec<f64> = slots
            .iter()
            .map(|&s| self.speeds[s] / total_speed)
            .collect();
        let mut feed = Feed::new(costs);
        let mut tasks: Vec<Option<T>> = tasks.into_iter().map(Some).collect();
        let mut results: Vec<Option<R>> = (0..tasks.len()).map(|_| None).collect();
        let mut held: Vec<VecDeque<Vec<usize>>> = vec![VecDeque::new(); slots.len()];
        let mut posted = Vec::new();
        let mut own = Vec::new();
        let (mut own_s, mut own_cost, mut total_busy) = (0.0, 0.0, 0.0);
        // Hands worker `k` chunks until it holds `CHUNKS_IN_FLIGHT`.
        macro_rules! refill {
            ($k:expr) => {
                while held[$k].len() < CHUNKS_IN_FLIGHT {
                    let Some(chunk) = feed.chunk(costs, speed_share[$k]) else {
                        break;
                    };
                    let share: Vec<T> = chunk
                        .iter()
                        .map(|&i| tasks[i].take().expect("handed out once"))
                        .collect();
                    let cost: f64 = chunk.iter().map(|&i| costs[i]).sum();
                    self.book[slots[$k]].cost_s += cost;
                    let rank = self.roles.workers[slots[$k] - 1];
                    self.post(rank, &make(share), &mut posted);
                    held[$k].push_back(chunk);
                }
            };
        }
        // Takes worker `k`'s answer to `chunk`, its oldest.
        macro_rules! take_reply {
            ($k:expr, $chunk:expr) => {{
                let chunk: Vec<usize> = $chunk;
                let (rs, busy) = self.gather(slots[$k], &chunk, costs, &unpack);
                total_busy += busy;
                for (r, i) in rs.into_iter().zip(chunk) {
                    results[i] = Some(r);
                }
            }};
        }
        // Takes every answer that has arrived and hands its worker the next
        // chunk: posted first, so that the worker steps it while rank 0
        // reads the answer.
        macro_rules! serve {
            () => {
                for k in 0..slots.len() {
                    let rank = self.roles.workers[slots[k] - 1];
                    while !held[k].is_empty()
                        && self
                            .world
                            .process_at_rank(rank)
                            .immediate_probe_with_tag(protocol::TAG_REPLY)
                            .is_some()
                    {
                        let answered = held[k].pop_front().expect("a chunk is held");
                        refill!(k);
                        take_reply!(k, answered);
                    }
                }
            };
        }
        for k in 0..slots.len() {
            refill!(k);
        }
        loop {
            serve!();
            self.reap_posts(&mut posted, false);
            let Some(i) = feed.own(costs) else { break };
            let task = tasks[i].take().expect("handed out once");
            let clock = Instant::now();
            // Rank 0's own task serves the workers as it goes (`POLL_EVERY`):
            // a worker done with its chunk gets the next one then, not only
            // once this task ends (a group step takes up to milliseconds,
            // and with many workers each would wait for it).
            let mut polled = clock;
            let mut poll = || {
                if polled.elapsed() >= POLL_EVERY {
                    serve!();
                    polled = Instant::now();
                }
            };
            let r = local(task, &mut poll);
            results[i] = Some(r);
            own_s += clock.elapsed().as_secs_f64();
            own_cost += costs[i];
            own.push(i);
        }
        // Everything is handed out: gather what the workers still hold.
        let wait = Instant::now();
        for k in 0..slots.len() {
            while let Some(chunk) = held[k].pop_front() {
                take_reply!(k, chunk);
            }
        }
        self.reap_posts(&mut posted, true);
        self.book[0].busy_s += own_s;
        self.book[0].cost_s += own_cost;
        self.book[0].waiting_s += wait.elapsed().as_secs_f64();
        self.meter(0, own_cost, own_s);
        own.sort_unstable();
        let results = results
            .into_iter()
            .map(|r| r.expect("every task answered"))
            .collect();
        (results, total_busy + own_s, own)
    }

    /// Slot `slot`'s answer to its `tasks` (indices into `costs`): received,
    /// checked to be the stage's reply with one result per task, and its
    /// busy time booked and metered. Returns the results and that time.
    fn gather<R>(
        &mut self,
        slot: usize,
        tasks: &[usize],
        costs: &[f64],
        unpack: &impl Fn(Reply) -> Option<(Vec<R>, f64)>,
    ) -> (Vec<R>, f64) {
        let rank = self.roles.workers[slot - 1];
        let Some((rs, busy)) = unpack(self.receive(rank)) else {
            eprintln!("rigidsim: rank 0: rank {rank} answered the wrong message");
            self.world.abort(4);
        };
        if rs.len() != tasks.len() {
            eprintln!(
                "rigidsim: rank 0: rank {rank} returned {} results for {} tasks",
                rs.len(),
                tasks.len()
            );
            self.world.abort(4);
        }
        let cost: f64 = tasks.iter().map(|&i| costs[i]).sum();
        self.book[slot].busy_s += busy;
        self.meter(slot, cost, busy);
        (rs, busy)
    }

    /// Updates a slot's speed from its batches (see `SpeedMeter`). The cost
    /// model is calibrated on all ranks' time together, so speeds average
    /// about 1 and a rank's share follows its speed alone.
    fn meter(&mut self, slot: usize, cost: f64, busy: f64) {
        if busy > 0.0 && cost > 0.0 {
            let meter = &mut self.meters[slot];
            meter.add(cost, busy);
            self.speeds[slot] = meter.speed().clamp(1e-3, 1e3);
        }
    }

    /// Tells workers and renderer to stop; collects their reports.
    pub fn stop(&mut self) -> Vec<(i32, WorkerReport)> {
        let mut reports = Vec::new();
        for &w in &self.roles.workers.clone() {
            self.send(w, &Req::Stop);
            if let Reply::Report(r) = self.receive(w) {
                reports.push((w, r));
            }
        }
        reports
    }

    pub fn summaries(&self, workers: &[(i32, WorkerReport)]) -> Vec<RankSummary> {
        let mut out = vec![RankSummary {
            rank: 0,
            role: "coordinator".into(),
            busy_s: self.book[0].busy_s,
            waiting_s: self.book[0].waiting_s,
            tasks: self.book[0].tasks_np + self.book[0].tasks_is,
            narrowphase_tasks: self.book[0].tasks_np,
            island_tasks: self.book[0].tasks_is,
            estimated_cost_s: self.book[0].cost_s,
            bytes_sent: self.book.iter().map(|b| b.bytes_sent).sum(),
            bytes_received: self.book.iter().map(|b| b.bytes_received).sum(),
            speed: self.speeds[0],
            frames_rendered: 0,
        }];
        for (k, &w) in self.roles.workers.iter().enumerate() {
            let rep = workers
                .iter()
                .find(|(r, _)| *r == w)
                .map(|(_, r)| r.clone())
                .unwrap_or_default();
            out.push(RankSummary {
                rank: w as u32,
                role: "worker".into(),
                busy_s: rep.busy_s,
                waiting_s: rep.waiting_s,
                tasks: rep.narrowphase_tasks + rep.island_tasks,
                narrowphase_tasks: rep.narrowphase_tasks,
                island_tasks: rep.island_tasks,
                estimated_cost_s: self.book[k + 1].cost_s,
                bytes_sent: rep.bytes_sent,
                bytes_received: rep.bytes_received,
                speed: self.speeds[k + 1],
                frames_rendered: 0,
            });
        }
        out
    }
}

impl Executor for MpiExecutor<'_> {
    fn share_forces(&mut self, forces: &[ForceWindow]) {
        let req = Req::Forces {
            forces: forces.to_vec(),
        };
        for &w in &self.roles.workers.clone() {
            self.send(w, &req);
        }
        for &w in &self.roles.workers.clone() {
            let _ = self.receive(w);
        }
    }

    fn finish(&mut self) -> (Vec<RankSummary>, Distribution) {
        let reports = self.stop();
        (self.summaries(&reports), self.dist.clone())
    }

    fn narrowphase(&mut self, objects: &[ObjectDef], tasks: Vec<PairTask>) -> Vec<PairResult> {
        self.clock.enter();
        let mark = self.traffic_mark(Stage::Narrowphase);
        let r = self.narrowphase_stage(objects, tasks);
        self.learn_traffic(Stage::Narrowphase, mark);
        self.dist.distributable_s += self.clock.leave();
        r
    }

    fn solve_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        self.clock.enter();
        let mark = self.traffic_mark(Stage::SolveIslands);
        let r = self.solve_islands_stage(tasks);
        self.learn_traffic(Stage::SolveIslands, mark);
        self.dist.distributable_s += self.clock.leave();
        r
    }

    fn step_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<GroupReply> {
        self.clock.enter();
        let mark = self.traffic_mark(Stage::StepGroups);
        let r = self.step_groups_stage(st, params, inputs);
        self.learn_traffic(Stage::StepGroups, mark);
        self.dist.distributable_s += self.clock.leave();
        r
    }

    fn prepare_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<PreparedPairs> {
        self.clock.enter();
        let mark = self.traffic_mark(Stage::StepGroups);
        let r = self.prepare_groups_stage(st, params, inputs);
        self.learn_traffic(Stage::StepGroups, mark);
        self.dist.distributable_s += self.clock.leave();
        r
    }

    fn split_groups(&mut self, groups: &[(f64, usize)]) -> Vec<bool> {
        let none = vec![false; groups.len()];
        if !self.split_where_it_pays {
            return none;
        }
        // A group predicted above each rank's fair share of the step's
        // group work, where the group steps would go out now, would hold
        // the other ranks up.
        let total: f64 = groups.iter().map(|&(c, _)| c).sum();
        let (_, workers) = self.group_workers(total, groups.len());
        if workers == 0 {
            return none;
        }
        let fair = total / (1 + workers) as f64;
        // `--force-distribute` (a test aid) takes every group that may be
        // split at all, so that small scenes take this path too.
        let fewest = if self.force_distribute {
            SPLIT_MIN_MEMBERS
        } else {
            SPLIT_AUTO_MIN_MEMBERS
        };
        let above: Vec<bool> = groups
            .iter()
            .map(|&(c, members)| c > fair && members >= fewest)
            .collect();
        if !above.contains(&true) {
            return above;
        }
        // Whether it pays is measured: on a settled pile the split groups'
        // steps share out, while bodies pour in their parts meet so often
        // that the runs lost cost more than the sharing gains.
        let split = self.split_choice.goes_out();
        self.split_step = Some((split, total, Instant::now()));
        if split {
            self.dist.steps_split += 1;
            above
        } else {
            self.dist.steps_kept_whole += 1;
            none
        }
    }

    fn groups_stepped(&mut self) {
        if let Some((split, cost, started)) = self.split_step.take() {
            self.split_choice
                .record(split, cost, started.elapsed().as_secs_f64());
        }
    }
}

impl MpiExecutor<'_> {
    /// Workers for a group stage of `total` predicted seconds over `tasks`
    /// tasks: (the cost model's, the one taken), the measured times
    /// (`group_choice`, `StageChoice`) sending it out where the model
    /// would keep it on rank 0.
    fn group_workers(&self, total: f64, tasks: usize) -> (usize, usize) {
        let modelled =
            self.workers_for_stage(Stage::StepGroups, total, tasks, SELF_SCHEDULED_SHARE);
        let workers = self
            .group_choice
            .workers(modelled, self.workers_without_link(total), tasks);
        (modelled, workers)
    }
}

impl MpiExecutor<'_> {
    fn narrowphase_stage(
        &mut self,
        objects: &[ObjectDef],
        tasks: Vec<PairTask>,
    ) -> Vec<PairResult> {
        let units: Vec<f64> = tasks
            .iter()
            .map(|t| {
                let (a, b) = (t.object_a as usize, t.object_b as usize);
                schedule::pair_units(
                    t.warm.len(),
                    self.parts[a],
                    self.parts[b],
                    self.polygons[a],
                    self.polygons[b],
                )
            })
            .collect();
        let costs: Vec<f64> = units.iter().map(|u| u * self.model.pair_coef).collect();
        let total: f64 = costs.iter().sum();
        let workers = self.workers_for(total, tasks.len());
        if workers == 0 {
            self.dist.narrowphase_local += 1;
            let clock = Instant::now();
            let r: Vec<PairResult> = tasks
                .iter()
                .map(|t| narrowphase::query_pair(objects, t))
                .collect();
            let s = clock.elapsed().as_secs_f64();
            self.model.calibrate_pairs(units.iter().sum(), s);
            self.book[0].busy_s += s;
            self.book[0].tasks_np += tasks.len() as u64;
            return r;
        }
        self.dist.narrowphase_distributed += 1;
        let (results, total_busy, own_tasks) = self.distribute(
            workers,
            COORDINATOR_SHARE,
            tasks,
            &costs,
            |share| Req::Narrowphase { tasks: share },
            |own| {
                own.iter()
                    .map(|t| narrowphase::query_pair(objects, t))
                    .collect()
            },
            |reply| match reply {
                Reply::Narrowphase { results, busy_s } => Some((results, busy_s)),
                _ => None,
            },
        );
        self.model.calibrate_pairs(units.iter().sum(), total_busy);
        self.book[0].tasks_np += own_tasks.len() as u64;
        results
    }

    fn solve_islands_stage(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        let units: Vec<f64> = tasks
            .iter()
            .map(|t| {
                let rows: usize = t
                    .contacts
                    .iter()
                    .map(|c| if c.friction > 0.0 { 3 } else { 1 })
                    .sum();
                schedule::island_units(rows)
            })
            .collect();
        let costs: Vec<f64> = units.iter().map(|u| u * self.model.island_coef).collect();
        let total: f64 = costs.iter().sum();
        // Self-scheduled: rank 0 works at its full speed (as for groups).
        let modelled = self.workers_for_stage(
            Stage::SolveIslands,
            total,
            tasks.len(),
            SELF_SCHEDULED_SHARE,
        );
        // Where measured times send the solves out, as for the group steps.
        let workers =
            self.solve_choice
                .workers(modelled, self.workers_without_link(total), tasks.len());
        if workers > 0 && modelled == 0 {
            self.dist.solves_by_measure += 1;
        }
        let started = Instant::now();
        if workers == 0 {
            self.dist.solve_local += 1;
            let r: Vec<IslandResult> = tasks.iter().map(solver::solve_island).collect();
            let s = started.elapsed().as_secs_f64();
            self.model.calibrate_islands(units.iter().sum(), s);
            self.book[0].busy_s += s;
            self.book[0].tasks_is += tasks.len() as u64;
            self.solve_choice.record(false, total, s);
            return r;
        }
        self.dist.solve_distributed += 1;
        let (results, total_busy, own_tasks) = self.self_schedule(
            workers,
            tasks,
            &costs,
            |share| Req::SolveIslands { tasks: share },
            |own, _| solver::solve_island(&own),
            |reply| match reply {
                Reply::SolveIslands { results, busy_s } => Some((results, busy_s)),
                _ => None,
            },
        );
        self.model.calibrate_islands(units.iter().sum(), total_busy);
        self.book[0].tasks_is += own_tasks.len() as u64;
        self.solve_choice
            .record(true, total, started.elapsed().as_secs_f64());
        results
    }

    /// Workers a self-scheduled stage of this estimated cost takes where
    /// its measured times send it out (`StageChoice`): those the model would
    /// use without the link's bytes (a much slower worker stays left out),
    /// at least one.
    fn workers_without_link(&self, estimated_s: f64) -> usize {
        if self.roles.workers.is_empty() {
            0
        } else {
            schedule::workers_to_use(
                estimated_s,
                &self.speeds,
                SELF_SCHEDULED_SHARE,
                self.latency_s,
            )
            .max(1)
        }
    }

    fn step_groups_stage(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<GroupReply> {
        // Seconds, from what the same bodies' groups took last step.
        let costs: Vec<f64> = inputs.iter().map(GroupInput::predicted_s).collect();
        let total: f64 = costs.iter().sum();
        let (modelled, workers) = self.group_workers(total, inputs.len());
        if workers > 0 && modelled == 0 {
            self.dist.groups_by_measure += 1;
        }
        let started = Instant::now();
        let replies = self.step_groups_on(st, params, inputs, costs, workers);
        self.group_choice
            .record(workers > 0, total, started.elapsed().as_secs_f64());
        replies
    }

    /// The group steps on rank 0 alone (`workers` = 0) or self-scheduled
    /// over rank 0 and `workers` workers.
    fn step_groups_on(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
        costs: Vec<f64>,
        workers: usize,
    ) -> Vec<GroupReply> {
        if workers == 0 {
            // On rank 0, whose executor (this one) still scatters the
            // groups' own narrowphase batches and island solves where they
            // pay; those count their own tasks and busy time.
            self.dist.groups_local += 1;
            return inputs
                .into_iter()
                .map(|input| run_group(st, input, self))
                .collect();
        }
        self.dist.groups_distributed += 1;
        let (inputs, costs) = self.prepare_large_groups(st, params, workers, inputs, costs);
        let (replies, _, own) = self.self_schedule(
            workers,
            inputs,
            &costs,
            |share| Req::StepGroups {
                params: params.clone(),
                inputs: share,
            },
            |input, poll| run_group(st, input, &mut Polled::new(poll)),
            |reply| match reply {
                Reply::StepGroups { replies, busy_s } => Some((replies, busy_s)),
                _ => None,
            },
        );
        for &i in &own {
            let (pairs, islands) = replies[i].tasks();
            self.book[0].tasks_np += pairs;
            self.book[0].tasks_is += islands;
        }
        replies
    }
}

impl MpiExecutor<'_> {
    /// The first stage of each of these groups for all its pairs, before
    /// they are split (`Executor::prepare_groups`): on rank 0 alone, or
    /// each group's pairs cut into ranges (`prepared_cuts`) and self-scheduled,
    /// as for `prepare_large_groups`.
    fn prepare_groups_stage(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<PreparedPairs> {
        let costs: Vec<f64> = inputs
            .iter()
            .map(|i| i.predicted_s() * FIRST_STAGE_SHARE)
            .collect();
        let total: f64 = costs.iter().sum();
        let pairs: usize = inputs.iter().map(GroupInput::pair_count).sum();
        let (_, workers) = self.group_workers(total, pairs);
        if workers == 0 {
            let clock = Instant::now();
            let prepared: Vec<PreparedPairs> = inputs
                .iter()
                .map(|input| {
                    prepare_pairs(st, input, (0, input.pair_count()), &mut Inline::default())
                })
                .collect();
            self.book[0].busy_s += clock.elapsed().as_secs_f64();
            self.book[0].tasks_np += prepared.iter().map(PreparedPairs::tasks).sum::<u64>();
            return prepared;
        }
        let ranks = workers + 1;
        let jobs: Vec<(usize, usize, f64)> = (0..inputs.len())
            .map(|g| {
                let pairs = inputs[g].pair_count();
                let cuts = if pairs >= ranks * MIN_PREPARED_PAIRS {
                    prepared_cuts(pairs, ranks)
                } else {
                    1
                };
                (g, cuts, costs[g])
            })
            .collect();
        self.prepare_in_ranges(st, params, workers, &inputs, &jobs)
    }

    /// The first stage of each group of `jobs` (index into `inputs`, the
    /// number of ranges its pairs are cut into, its estimated seconds),
    /// self-scheduled over rank 0 and `workers` workers (`PreparePairs`);
    /// each group's answers joined, in the order of `jobs`.
    fn prepare_in_ranges(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        workers: usize,
        inputs: &[GroupInput],
        jobs: &[(usize, usize, f64)],
    ) -> Vec<PreparedPairs> {
        let mut shares: Vec<(usize, (usize, usize))> = Vec::new();
        let mut share_costs = Vec::new();
        for &(g, cuts, cost) in jobs {
            let n = inputs[g].pair_count();
            for r in 0..cuts {
                shares.push((g, (r * n / cuts, (r + 1) * n / cuts)));
                share_costs.push(cost / cuts as f64);
            }
        }
        self.dist.groups_prepared += jobs.iter().filter(|&&(_, cuts, _)| cuts > 1).count() as u64;
        let (prepared, _, own) = self.self_schedule(
            workers,
            shares.clone(),
            &share_costs,
            |share| {
                // Each group's input once, however many of its ranges.
                let mut groups: Vec<usize> = share.iter().map(|&(g, _)| g).collect();
                groups.sort_unstable();
                groups.dedup();
                Req::PreparePairs {
                    params: params.clone(),
                    inputs: groups.iter().map(|&g| inputs[g].clone()).collect(),
                    shares: share
                        .into_iter()
                        .map(|(g, range)| (groups.binary_search(&g).expect("listed") as u32, range))
                        .collect(),
                }
            },
            |(g, range), poll| prepare_pairs(st, &inputs[g], range, &mut Polled::new(poll)),
            |reply| match reply {
                Reply::PreparePairs { prepared, busy_s } => Some((prepared, busy_s)),
                _ => None,
            },
        );
        for &i in &own {
            self.book[0].tasks_np += prepared[i].tasks();
        }
        let mut by_group: BTreeMap<usize, Vec<PreparedPairs>> = BTreeMap::new();
        for ((g, _), p) in shares.into_iter().zip(prepared) {
            by_group.entry(g).or_default().push(p);
        }
        jobs.iter()
            .map(|&(g, _, _)| PreparedPairs::joined(by_group.remove(&g).unwrap_or_default()))
            .collect()
    }

    /// A group predicted to take more than its ranks' fair share cannot be
    /// balanced whole: the first stage of its step (each pair's end-of-step
    /// result and time of impact, `prepare_pairs`; about half of a pile's
    /// step) goes out first, its pairs cut into ranges (`prepared_cuts`), and the
    /// group then steps its events from those answers wherever it goes.
    /// Returns the inputs and their costs for the group steps that follow.
    fn prepare_large_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        workers: usize,
        mut inputs: Vec<GroupInput>,
        mut costs: Vec<f64>,
    ) -> (Vec<GroupInput>, Vec<f64>) {
        let ranks = workers + 1;
        let fair = costs.iter().sum::<f64>() / ranks as f64;
        let large: Vec<usize> = (0..inputs.len())
            .filter(|&g| {
                let pairs = inputs[g].pair_count();
                if inputs[g].is_prepared() {
                    false
                } else if self.force_distribute {
                    // Tests of determinism: every group that can be cut is.
                    pairs >= ranks
                } else {
                    pairs >= ranks * MIN_PREPARED_PAIRS && costs[g] > fair
                }
            })
            .collect();
        if large.is_empty() {
            return (inputs, costs);
        }
        // Each large group's pairs in ranges, costed by the first
        // stage's share of the group's predicted time.
        let jobs: Vec<(usize, usize, f64)> = large
            .iter()
            .map(|&g| {
                let cuts = prepared_cuts(inputs[g].pair_count(), ranks);
                (g, cuts, costs[g] * FIRST_STAGE_SHARE)
            })
            .collect();
        let prepared = self.prepare_in_ranges(st, params, workers, &inputs, &jobs);
        for (&g, p) in large.iter().zip(prepared) {
            inputs[g].set_prepared(p);
            costs[g] *= 1.0 - FIRST_STAGE_SHARE;
        }
        (inputs, costs)
    }
}

/// Share of a large group's step its first stage takes (`prepare_pairs`;
/// measured on the 200-body pour's pile: 0.4–0.5).
const FIRST_STAGE_SHARE: f64 = 0.45;
/// A group's first stage is cut into ranges of at least this many pairs
/// per rank (below, messages cost more than the share saves).
const MIN_PREPARED_PAIRS: usize = 16;
/// Ranges per rank a large group's first stage is cut into (of at least
/// `MIN_PREPARED_PAIRS` / 2 pairs each), self-scheduled: the pairs' costs
/// are far from even (on the 200-body pour's pile the second half of the
/// pairs by body id took three times the first, the bodies dropped last
/// still falling fast), so one equal range per rank left the ranks with
/// the cheap ranges waiting.
const PREPARED_CUTS_PER_RANK: usize = 4;

/// How many ranges a group's first stage of `pairs` pairs is cut into,
/// over `ranks` ranks (`PREPARED_CUTS_PER_RANK`).
fn prepared_cuts(pairs: usize, ranks: usize) -> usize {
    (ranks * PREPARED_CUTS_PER_RANK)
        .min(pairs / (MIN_PREPARED_PAIRS / 2))
        .max(ranks)
}

/// The stages whose messages are costed by their bytes (`schedule::Link`).
#[derive(Clone, Copy, Debug)]
enum Stage {
    Narrowphase,
    SolveIslands,
    /// Group steps, with the `PreparePairs` shares sent before them.
    StepGroups,
}

/// Payload of one link-rate probe: large enough that its time on a
/// 100 Mbit/s link (5 ms each way) stands well above a round trip's, small
/// enough that three per worker over 10 Mbit/s take a third of a second.
const PROBE_BYTES: usize = 64 * 1024;
/// Probes of each size per worker (the fastest is kept).
const PROBES: usize = 3;

/// What the network costs, for the byte term of the cost model and for
/// naming hosts: each rank's host, each worker's link rate measured at
/// start-up, and per stage the bytes its messages carried per second of
/// work handed to workers.
#[derive(Default)]
struct Network {
    /// By rank; empty until `set_hosts`.
    hosts: Vec<String>,
    /// By slot (slot 0, rank 0 itself, unused); infinite where the probe
    /// took no longer than an empty round trip (shared memory).
    link_bytes_per_s: Vec<f64>,
    /// By `Stage`; 0 until the stage was distributed once.
    bytes_per_cost_s: [f64; 3],
}

/// Where a stage's traffic stood when it began (`MpiExecutor::traffic_mark`).
#[derive(Clone, Copy)]
struct TrafficMark {
    bytes: u64,
    worker_cost_s: f64,
    distributed: u64,
}

impl MpiExecutor<'_> {
    /// Each rank's host (`rank_hosts`), for messages and `summary.json`.
    pub fn set_hosts(&mut self, hosts: Vec<String>) {
        self.net.hosts = hosts;
    }

    fn host_of(&self, rank: i32) -> &str {
        self.net
            .hosts
            .get(rank as usize)
            .map_or("unknown", String::as_str)
    }

    /// The link rate measured to each rank (bytes per second; `None` for
    /// rank 0 and for ranks not measured or reached through shared memory),
    /// by rank.
    pub fn link_rates(&self) -> Vec<Option<f64>> {
        let mut rates = vec![None; self.roles.size as usize];
        for (k, &w) in self.roles.workers.iter().enumerate() {
            rates[w as usize] = self
                .net
                .link_bytes_per_s
                .get(k + 1)
                .copied()
                .filter(|r| r.is_finite());
        }
        rates
    }

    /// Each worker's link rate: twice `PROBE_BYTES` over the time an echo
    /// of them takes beyond an empty echo, each the fastest of `PROBES`
    /// (interleaved). The fastest, not the median: on shared cores a
    /// sample's extra time is mostly the worker waiting for a core, which
    /// says nothing of the link. Their bytes are not booked (they are not
    /// the run's traffic).
    fn measure_link_rates(&mut self) {
        let booked = self.book.clone();
        let mut rates = vec![f64::INFINITY; self.roles.workers.len() + 1];
        for (k, &w) in self.roles.workers.clone().iter().enumerate() {
            let (mut empty, mut full) = (f64::INFINITY, f64::INFINITY);
            for _ in 0..PROBES {
                for (bytes, best) in [(0, &mut empty), (PROBE_BYTES, &mut full)] {
                    let t = Instant::now();
                    self.send(
                        w,
                        &Req::Probe {
                            payload: vec![0u8; bytes],
                        },
                    );
                    let _ = self.receive(w);
                    *best = best.min(t.elapsed().as_secs_f64());
                }
            }
            if full > empty {
                rates[k + 1] = 2.0 * PROBE_BYTES as f64 / (full - empty);
            }
        }
        for (b, old) in self.book.iter_mut().zip(booked) {
            b.bytes_sent = old.bytes_sent;
            b.bytes_received = old.bytes_received;
        }
        self.net.link_bytes_per_s = rates;
    }

    /// Rank 0's link: the slowest measured path to a worker (every message
    /// passes through rank 0's link, so its rate bounds them all).
    fn link(&self, stage: Stage) -> schedule::Link {
        let bytes_per_s = self.net.link_bytes_per_s[1..]
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        schedule::Link {
            bytes_per_cost_s: self.net.bytes_per_cost_s[stage as usize],
            bytes_per_s,
        }
    }

    /// Workers a stage of this estimated cost should use, rank 0 counted at
    /// `share` of its speed, with the time the stage's bytes take on the
    /// link (`schedule::workers_to_use_over_link`). `--force-distribute`
    /// uses them all; fewer than two tasks stay on rank 0.
    fn workers_for_stage(&self, stage: Stage, estimated_s: f64, tasks: usize, share: f64) -> usize {
        let workers = self.roles.workers.len();
        if workers == 0 || tasks < 2 {
            return 0;
        }
        if self.force_distribute {
            return workers;
        }
        schedule::workers_to_use_over_link(
            estimated_s,
            &self.speeds,
            share,
            self.latency_s,
            &self.link(stage),
        )
    }

    fn distributed_count(&self, stage: Stage) -> u64 {
        match stage {
            Stage::Narrowphase => self.dist.narrowphase_distributed,
            Stage::SolveIslands => self.dist.solve_distributed,
            Stage::StepGroups => self.dist.groups_distributed,
        }
    }

    fn traffic_mark(&self, stage: Stage) -> TrafficMark {
        TrafficMark {
            bytes: self
                .book
                .iter()
                .map(|b| b.bytes_sent + b.bytes_received)
                .sum(),
            worker_cost_s: self.book[1..].iter().map(|b| b.cost_s).sum(),
            distributed: self.distributed_count(stage),
        }
    }

    /// After a stage that went to workers: the bytes it moved per second of
    /// the work it handed them, smoothed over the last few such stages.
    fn learn_traffic(&mut self, stage: Stage, mark: TrafficMark) {
        if self.distributed_count(stage) == mark.distributed {
            return;
        }
        let now = self.traffic_mark(stage);
        let cost = now.worker_cost_s - mark.worker_cost_s;
        let bytes = (now.bytes - mark.bytes) as f64;
        if cost <= 0.0 || bytes <= 0.0 {
            return;
        }
        let old = &mut self.net.bytes_per_cost_s[stage as usize];
        let measured = bytes / cost;
        *old = if *old > 0.0 {
            0.8 * *old + 0.2 * measured
        } else {
            measured
        };
    }
}

/// Each rank's host name, gathered on rank 0 (by rank; empty elsewhere).
/// Every rank calls it once at start-up, before the roles part.
pub fn rank_hosts(world: &SimpleCommunicator) -> Vec<String> {
    gather_names::<64>(world, &hostname())
}

/// Each rank's `vector_units`, gathered on rank 0 like `rank_hosts`.
pub fn rank_vector_units(world: &SimpleCommunicator) -> Vec<String> {
    gather_names::<16>(world, vector_units())
}

/// `own` from every rank (cut to LEN bytes), by rank on rank 0; empty on
/// the others. A collective: every rank calls it at the same point.
fn gather_names<const LEN: usize>(world: &SimpleCommunicator, own: &str) -> Vec<String> {
    use mpi::collective::Root;
    let mut name = [0u8; LEN];
    let n = own.len().min(LEN);
    name[..n].copy_from_slice(&own.as_bytes()[..n]);
    let root = world.process_at_rank(0);
    if world.rank() != 0 {
        root.gather_into(&name[..]);
        return Vec::new();
    }
    let mut all = vec![0u8; LEN * world.size() as usize];
    root.gather_into_root(&name[..], &mut all[..]);
    all.chunks(LEN)
        .map(|c| {
            let end = c.iter().position(|&b| b == 0).unwrap_or(LEN);
            String::from_utf8_lossy(&c[..end]).into_owned()
        })
        .collect()
}

/// The widest vector instructions of this CPU among those faer's kernels
/// choose between when they run (its products: AVX-512, AVX2 with FMA, or
/// SSE2). Two ranks whose CPUs differ here may round a supernodal or dense
/// factorisation differently (`docs/architecture.md`, *Determinism*).
pub fn vector_units() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            "avx512f"
        } else if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            "avx2+fma"
        } else {
            "sse2"
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        std::env::consts::ARCH
    }
}

/// A warning, when the ranks' CPUs differ in `vector_units`: results may
/// then depend on where each task ran. Rank 0 prints it at start-up and
/// `summary.json` keeps it in `notes`.
pub fn mixed_vector_units_line(units: &[String]) -> Option<String> {
    let groups = ranks_by(units);
    (groups.len() > 1).then(|| {
        format!(
            "warning: the ranks' CPUs differ in vector units ({}); faer's \
             factorisations choose their code by them, so a run whose contact \
             systems reach those (large dense blocks, as the pyramid's) can end \
             on another state hash than on PCs of one kind (docs/architecture.md, \
             Determinism)",
            groups_text(&groups)
        )
    })
}

/// Ranks grouped by their value, in order of first appearance.
fn ranks_by(values: &[String]) -> Vec<(&str, Vec<usize>)> {
    let mut groups: Vec<(&str, Vec<usize>)> = Vec::new();
    for (rank, value) in values.iter().enumerate() {
        match groups.iter_mut().find(|(v, _)| v == value) {
            Some((_, ranks)) => ranks.push(rank),
            None => groups.push((value, vec![rank])),
        }
    }
    groups
}

/// "value: 0, 1; other: 2".
fn groups_text(groups: &[(&str, Vec<usize>)]) -> String {
    let parts: Vec<String> = groups
        .iter()
        .map(|(v, ranks)| {
            let r: Vec<String> = ranks.iter().map(|r| r.to_string()).collect();
            format!("{v}: {}", r.join(", "))
        })
        .collect();
    parts.join("; ")
}

/// Which ranks run on which host, in one line, when they run on more than
/// one: rank 0 prints it at start-up, so that a job mpirun ends for a lost
/// host (its message names the host, not the ranks) says whose ranks they were.
pub fn hosts_line(hosts: &[String]) -> Option<String> {
    let groups = ranks_by(hosts);
    (groups.len() > 1).then(|| format!("ranks by host: {}", groups_text(&groups)))
}

/// This machine's host name (its UTS name: a lab's "PC" has its own).
pub fn hostname() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: `buf` is writable for its length; gethostname NUL-terminates
    // names shorter than it.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if rc != 0 {
        return "unknown".into();
    }
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    String::from_utf8_lossy(&buf[..end]).into_owned()
}

/// A worker rank: answers requests from rank 0 until `Stop`.
pub fn worker_loop(world: &SimpleCommunicator, scene: &Scene, slow: f64) {
    let root = world.process_at_rank(0);
    let mut report = WorkerReport::default();
    // The scene with the forces rank 0 last shared (`Req::Forces`), once it
    // has shared any.
    let mut shared: Option<Scene> = None;
    loop {
        let wait = Instant::now();
        let (bytes, _) = root.receive_vec_with_tag::<u8>(protocol::TAG_REQUEST);
        report.waiting_s += wait.elapsed().as_secs_f64();
        report.bytes_received += bytes.len() as u64;
        let req: Req = match decode(&bytes) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("rigidsim: rank {}: {e}", world.rank());
                world.abort(4);
            }
        };
        let clock = Instant::now();
        let cpu = if slow > 1.0 {
            thread_cpu_time()
        } else {
            Duration::ZERO
        };
        if let Req::Forces { forces } = req {
            shared.get_or_insert_with(|| scene.clone()).forces = forces;
            let out = encode(&Reply::Pong);
            report.bytes_sent += out.len() as u64;
            root.send_with_tag(&out[..], protocol::TAG_REPLY);
            continue;
        }
        let scene = shared.as_ref().unwrap_or(scene);
        let reply = match req {
            Req::Forces { .. } => unreachable!("answered above"),
            Req::Ping => Reply::Pong,
            Req::Probe { payload } => {
                // Not the run's traffic (see `Req::Probe`).
                report.bytes_received -= bytes.len() as u64;
                Reply::Probe { payload }
            }
            Req::Stop => Reply::Report(report.clone()),
            Req::Narrowphase { tasks } => {
                report.narrowphase_tasks += tasks.len() as u64;
                let results = tasks
                    .iter()
                    .map(|t| narrowphase::query_pair(&scene.objects, t))
                    .collect();
                let busy = stall(slow, clock, cpu).as_secs_f64();
                report.busy_s += busy;
                Reply::Narrowphase {
                    results,
                    busy_s: busy,
                }
            }
            Req::StepGroups { params, inputs } => {
                let st = params.statics(scene);
                let mut inline = Inline::default();
                let replies: Vec<GroupReply> = inputs
                    .into_iter()
                    .map(|input| run_group(&st, input, &mut inline))
                    .collect();
                for r in &replies {
                    let (pairs, islands) = r.tasks();
                    report.narrowphase_tasks += pairs;
                    report.island_tasks += islands;
                }
                let busy = stall(slow, clock, cpu).as_secs_f64();
                report.busy_s += busy;
                Reply::StepGroups {
                    replies,
                    busy_s: busy,
                }
            }
            Req::PreparePairs {
                params,
                inputs,
                shares,
            } => {
                let st = params.statics(scene);
                let prepared: Vec<PreparedPairs> = shares
                    .iter()
                    .map(|&(i, range)| {
                        prepare_pairs(&st, &inputs[i as usize], range, &mut Inline::default())
                    })
                    .collect();
                report.narrowphase_tasks += prepared.iter().map(PreparedPairs::tasks).sum::<u64>();
                let busy = stall(slow, clock, cpu).as_secs_f64();
                report.busy_s += busy;
                Reply::PreparePairs {
                    prepared,
                    busy_s: busy,
                }
            }
            Req::SolveIslands { tasks } => {
                report.island_tasks += tasks.len() as u64;
                let results = tasks.iter().map(solver::solve_island).collect();
                let busy = stall(slow, clock, cpu).as_secs_f64();
                report.busy_s += busy;
                Reply::SolveIslands {
                    results,
                    busy_s: busy,
                }
            }
        };
        let stop = matches!(reply, Reply::Report(_));
        let out = encode(&reply);
        if !matches!(reply, Reply::Probe { .. }) {
            report.bytes_sent += out.len() as u64;
        }
        root.send_with_tag(&out[..], protocol::TAG_REPLY);
        if stop {
            return;
        }
    }
}

/// A frame's send on its way to the renderer, and its buffer (freed once
/// the send completes).
type FrameInFlight = (Request<'static, [u8], StaticScope>, *mut [u8]);

/// Frames the renderer holds at most; beyond this the oldest are dropped
/// (and counted), so a slow renderer never queues without bound.
pub const RENDER_QUEUE: usize = 64;
/// Sends rank 0 keeps in flight at most (MPI copies small frames eagerly, so
/// this bounds rank 0's buffers; the renderer's queue bounds the backlog).
const MAX_FRAMES_IN_FLIGHT: usize = 64;

/// Rank 0's side of the render stream: non-blocking sends with a bounded
/// queue, so rendering never slows the simulation; when the renderer falls
/// behind, frames are dropped and counted.
pub struct RemoteFrames<'w> {
    world: &'w SimpleCommunicator,
    renderer: i32,
    /// The render rank's host, for the message if it stops answering.
    host: String,
    in_flight: Vec<FrameInFlight>,
    pub dropped: u64,
    pub bytes_sent: u64,
    report: Option<RenderReport>,
    /// Set when the render rank stopped answering in `finish`.
    lost: Option<String>,
}

impl<'w> RemoteFrames<'w> {
    pub fn new(world: &'w SimpleCommunicator, renderer: i32, host: String) -> Self {
        RemoteFrames {
            world,
            renderer,
            host,
            in_flight: Vec::new(),
            dropped: 0,
            bytes_sent: 0,
            report: None,
            lost: None,
        }
    }

    /// Completes finished sends and frees their buffers; whether any did.
    fn reap(&mut self) -> bool {
        let before = self.in_flight.len();
        let mut still = Vec::new();
        for (req, buf) in self.in_flight.drain(..) {
            match req.test() {
                // SAFETY: the buffer was leaked from a Box in `post` and MPI is
                // done with it once the request completed.
                Ok(_) => drop(unsafe { Box::from_raw(buf) }),
                Err(req) => still.push((req, buf)),
            }
        }
        self.in_flight = still;
        self.in_flight.len() < before
    }

    /// Waits for the render report without blocking inside MPI: while the
    /// last sends complete and the renderer's `TAG_RENDER_ALIVE` messages
    /// come, and no longer than `RENDER_DEADLINE` after the last of them,
    /// so a render rank that stopped (a frozen PC, a hung GPU driver) ends
    /// the job after the results are written instead of hanging it.
    fn await_report(&mut self) -> Option<RenderReport> {
        let renderer = self.world.process_at_rank(self.renderer);
        // Receives the signs of life that have arrived; whether there were any.
        let take_alive = || {
            let mut any = false;
            while renderer
                .immediate_probe_with_tag(protocol::TAG_RENDER_ALIVE)
                .is_some()
            {
                let _ = renderer.receive_vec_with_tag::<u8>(protocol::TAG_RENDER_ALIVE);
                any = true;
            }
            any
        };
        let mut heard = Instant::now();
        let mut spins = 0u32;
        loop {
            // (Both run: each completes what has arrived.)
            let sent = self.reap();
            if take_alive() | sent {
                heard = Instant::now();
            }
            if self.in_flight.is_empty()
                && renderer
                    .immediate_probe_with_tag(protocol::TAG_RENDER_REPORT)
                    .is_some()
            {
                let (bytes, _) = renderer.receive_vec_with_tag::<u8>(protocol::TAG_RENDER_REPORT);
                // Signs of life sent before the report have arrived before
                // it (same sender): none is left unreceived.
                take_alive();
                return Some(decode(&bytes).unwrap_or_default());
            }
            if heard.elapsed() > RENDER_DEADLINE {
                return None;
            }
            spins += 1;
            pause(spins);
        }
    }

    fn post(&mut self, msg: &RenderMessage) {
        let bytes = encode(msg).into_boxed_slice();
        self.bytes_sent += bytes.len() as u64;
        let raw: *mut [u8] = Box::into_raw(bytes);
        // SAFETY: `raw` stays allocated until the request completes (see `reap`).
        let buf: &'static [u8] = unsafe { &*raw };
        let req = self
            .world
            .process_at_rank(self.renderer)
            .immediate_send_with_tag(StaticScope, buf, protocol::TAG_FRAME);
        self.in_flight.push((req, raw));
    }
}

impl FrameSink for RemoteFrames<'_> {
    fn publish(&mut self, frame: Frame) {
        self.reap();
        if self.in_flight.len() >= MAX_FRAMES_IN_FLIGHT {
            self.dropped += 1;
            return;
        }
        self.post(&RenderMessage::Frame(frame));
    }

    fn expect_earlier(&mut self, digests: Vec<u64>) {
        self.reap();
        self.post(&RenderMessage::Earlier(digests));
    }

    fn lost(&self) -> Option<String> {
        self.lost.clone()
    }

    fn rank_summary(&self) -> Option<RankSummary> {
        let r = self.report.as_ref()?;
        Some(RankSummary {
            rank: self.renderer as u32,
            role: "renderer".into(),
            busy_s: r.busy_s,
            bytes_received: r.bytes_received,
            frames_rendered: r.rendered,
            speed: 1.0,
            ..Default::default()
        })
    }

    fn finish(&mut self, last: Frame) -> (u64, u64, Option<String>, Vec<String>) {
        self.post(&RenderMessage::Finish(last));
        let Some(report) = self.await_report() else {
            let why = format!(
                "render rank {} (on host {}) has not answered for {} s after the last frame; \
                 its frames, preview and video may be incomplete",
                self.renderer,
                self.host,
                RENDER_DEADLINE.as_secs()
            );
            // Said once, by the caller, after the results are written.
            self.lost = Some(why.clone());
            // The sends still in flight are left to MPI with their buffers
            // (MPI may yet read them; rsmpi panics on dropping an unfinished
            // request), and the job ends soon (`lost`).
            for (request, _buffer) in self.in_flight.drain(..) {
                std::mem::forget(request);
            }
            return (0, self.dropped, None, vec![why]);
        };
        self.report = Some(report.clone());
        (
            report.rendered,
            report.dropped + self.dropped,
            report.adapter,
            report.notes,
        )
    }
}

/// The render rank: draws every frame it receives; when several are waiting
/// it draws the newest and counts the others as dropped. Never sends back
/// until the final report.
pub fn renderer_loop(world: &SimpleCommunicator, scene: &Scene, out_dir: &Path) {
    let root = world.process_at_rank(0);
    let mut report = RenderReport::default();
    let mut renderer = match FrameRenderer::new(scene, out_dir) {
        Ok(r) => {
            report.adapter = Some(r.adapter());
            Some(r)
        }
        Err(e) => {
            eprintln!(
                "rigidsim: rank {} (renderer): {e}; frames will not be drawn",
                world.rank()
            );
            report.notes.push(format!("renderer unavailable: {e}"));
            None
        }
    };
    let mut queue: VecDeque<Frame> = VecDeque::new();
    let mut finish: Option<Frame> = None;
    // Once rank 0 has sent the last frame it waits for the report, and
    // takes each of these as a sign of life (`RENDER_DEADLINE`).
    let mut alive = || root.send_with_tag(&[0u8][..], protocol::TAG_RENDER_ALIVE);
    loop {
        // Take in everything that has arrived (blocking only when idle).
        while finish.is_none()
            && (queue.is_empty() || root.immediate_probe_with_tag(protocol::TAG_FRAME).is_some())
        {
            let (bytes, _) = root.receive_vec_with_tag::<u8>(protocol::TAG_FRAME);
            report.bytes_received += bytes.len() as u64;
            match decode::<RenderMessage>(&bytes) {
                Ok(RenderMessage::Frame(f)) => queue.push_back(f),
                Ok(RenderMessage::Earlier(digests)) => {
                    if let Some(r) = renderer.as_mut() {
                        r.expect_earlier(digests);
                    }
                }
                Ok(RenderMessage::Finish(last)) => finish = Some(last),
                Err(e) => eprintln!("rigidsim: renderer: {e}"),
            }
            while queue.len() > RENDER_QUEUE {
                queue.pop_front();
                report.dropped += 1;
            }
        }
        if let Some(f) = queue.pop_front() {
            if let Some(r) = renderer.as_mut() {
                let clock = Instant::now();
                if let Err(e) = r.render_frame(&f) {
                    report.notes.push(format!("frame {}: {e}", f.index));
                }
                report.busy_s += clock.elapsed().as_secs_f64();
            }
            if finish.is_some() {
                alive();
            }
            continue;
        }
        if let Some(last) = finish.take() {
            if let Some(r) = renderer.as_mut() {
                if let Err(e) = r.finish(&last, &mut alive) {
                    report.notes.push(format!("preview: {e}"));
                }
                report.rendered = r.rendered;
                report.notes.extend(r.notes.iter().cloned());
            }
            root.send_with_tag(&encode(&report)[..], protocol::TAG_RENDER_REPORT);
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn mixed_vector_units_are_named_by_rank_and_one_kind_says_nothing() {
        assert_eq!(mixed_vector_units_line(&names(&["avx2+fma"; 3])), None);
        assert_eq!(mixed_vector_units_line(&names(&["sse2"])), None);
        let line = mixed_vector_units_line(&names(&["avx2+fma", "sse2", "avx2+fma", "avx512f"]))
            .expect("mixed CPUs are reported");
        assert!(line.starts_with("warning: "), "{line}");
        assert!(
            line.contains("(avx2+fma: 0, 2; sse2: 1; avx512f: 3)"),
            "{line}"
        );
        assert!(!line.contains('\n'), "one line: {line}");
    }

    #[test]
    fn hosts_line_groups_ranks_by_host() {
        assert_eq!(hosts_line(&names(&["pc1", "pc1"])), None);
        assert_eq!(
            hosts_line(&names(&["pc1", "pc2", "pc1"])).as_deref(),
            Some("ranks by host: pc1: 0, 2; pc2: 1")
        );
    }

    #[test]
    fn this_cpu_has_a_known_name() {
        assert!(
            ["avx512f", "avx2+fma", "sse2"].contains(&vector_units())
                || !cfg!(target_arch = "x86_64")
        );
    }
}

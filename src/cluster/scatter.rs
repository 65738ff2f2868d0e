//! How rank 0 shares a stage's tasks out: the greedy plan (one message per
//! worker) and self-scheduling (chunks handed out as workers answer), and
//! the speeds measured from the answers.

use super::MpiExecutor;
use super::network::Stage;
use super::protocol::{self, Reply, Request as Req};
use super::schedule;
use mpi::point_to_point::Source;
use mpi::topology::Communicator;
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Share of its speed that rank 0 plans for itself (it also packs and merges).
pub(super) const COORDINATOR_SHARE: f64 = 0.5;
/// The same for the self-scheduled stages (island solves, group steps),
/// when deciding whether to distribute them: rank 0 works through tasks
/// while the workers work through theirs (`self_schedule`), so it counts at
/// full speed.
pub(super) const SELF_SCHEDULED_SHARE: f64 = 1.0;
/// Chunks of group steps a worker holds at most. Two (the one it steps and
/// the next, so that it never waits for rank 0 between them) would commit
/// the second chunk while little is known of the first, which costs more
/// than the wait saves.
const CHUNKS_IN_FLIGHT: usize = 1;
/// A chunk holds at least this share of the work not yet handed out, times
/// the worker's share of the speed of the ranks taking part (guided
/// self-scheduling): large chunks while much is left, few messages; small
/// ones at the end, where an estimate that was off could leave a rank
/// waiting. By speed, because a stage often ends with every worker's first
/// chunk, and equal chunks would leave it waiting for the slowest rank.
pub(super) const CHUNK_SHARE: f64 = 0.5;

/// How often rank 0 looks for answers while it steps a group of its own
/// (`Polled`): a probe per worker costs about a microsecond, and an event
/// calls the executor a few times.
const POLL_EVERY: Duration = Duration::from_micros(20);

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

impl MpiExecutor<'_> {
    /// Workers the pair tasks of this estimated cost should use (0: rank 0
    /// alone), from the measured round trip, the link's rate and the
    /// estimated speeds; see `schedule::workers_to_use_over_link`.
    /// `--force-distribute` uses them all.
    pub(super) fn workers_for(&self, estimated_s: f64, tasks: usize) -> usize {
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
    pub(super) fn distribute<T: Clone, R>(
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

    /// Scatter–compute–gather by self-scheduling (for group steps, whose
    /// costs are predictions from the last step and often off): the tasks
    /// sorted largest first, each worker holds up to `CHUNKS_IN_FLIGHT`
    /// chunks from the front and gets the next when it answers, and rank 0
    /// steps single tasks from the back in between, so no rank waits while
    /// work is left. Results are merged by task index, never by arrival
    /// order or by where a task ran. Returns the results and rank 0's
    /// tasks, in the order it ran them.
    pub(super) fn self_schedule<T, R>(
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
}

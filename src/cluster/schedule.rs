//! Cost model, rank speeds and assignment (SPEC 3.2–3.3).
//!
//! Costs are in seconds: a model unit (the thesis's polygon product for a
//! pair, contacts³ for a system) times a coefficient calibrated from the
//! coordinator's own measured work. A rank's speed is the cost it was given
//! over the time it reported busy, smoothed, so a PC that another user starts
//! loading gets less work from the next frame on.

#[derive(Clone, Debug)]
pub struct CostModel {
    /// Seconds per pair unit (see `pair_units`).
    pub pair_coef: f64,
    /// Seconds per unit of an island (rows³ + 20·rows).
    pub island_coef: f64,
    /// Smoothed sums behind the coefficients: (units, seconds).
    pair_sums: (f64, f64),
    island_sums: (f64, f64),
}

impl Default for CostModel {
    fn default() -> Self {
        // Start-up guesses (measured on the development machine); replaced by
        // measurements from the first frames on.
        CostModel {
            pair_coef: 5e-7,
            island_coef: 2e-8,
            pair_sums: (0.0, 0.0),
            island_sums: (0.0, 0.0),
        }
    }
}

/// Exact-collision cost of a body pair, in V-Clip part-pair queries.
///
/// The thesis priced a pair by the product of its polygon counts. Measured
/// here, that overweights big pairs by orders of magnitude: a V-Clip query
/// warm-started from the cached features takes about one step whatever the
/// polygon counts (1.01 iterations on average against 5.35 cold). So a pair
/// costs one unit per part pair it tested last frame (the length of its
/// feature cache, which travels with the task), and a pair never tested
/// before costs a cold query per part pair, whose walk grows with the
/// polygon counts (√(n_a·n_b)/8 units). Every pair also screens all its
/// part pairs by their spheres (a tenth of a unit each: a nut against a nut
/// is 32 × 32 sphere tests). The coefficient is calibrated in seconds from
/// measured times.
pub fn pair_units(
    cached_part_pairs: usize,
    parts_a: usize,
    parts_b: usize,
    polygons_a: usize,
    polygons_b: usize,
) -> f64 {
    let screening = 0.1 * (parts_a * parts_b) as f64;
    screening
        + if cached_part_pairs > 0 {
            1.0 + cached_part_pairs as f64
        } else {
            let per_part = ((polygons_a * polygons_b) as f64).sqrt()
                / (8.0 * (parts_a * parts_b) as f64).max(1.0);
            1.0 + (parts_a * parts_b) as f64 * per_part.max(1.0)
        }
}

impl CostModel {
    /// Seconds per unit as a ratio of smoothed sums: a batch of a few tiny
    /// tasks (mostly fixed overhead) cannot swing the estimate.
    pub fn calibrate_pairs(&mut self, units: f64, seconds: f64) {
        if let Some(c) = calibrate(&mut self.pair_sums, units, seconds) {
            self.pair_coef = c;
        }
    }
    pub fn calibrate_islands(&mut self, units: f64, seconds: f64) {
        if let Some(c) = calibrate(&mut self.island_sums, units, seconds) {
            self.island_coef = c;
        }
    }
}

fn calibrate(sums: &mut (f64, f64), units: f64, seconds: f64) -> Option<f64> {
    if !(units > 0.0 && seconds > 0.0) {
        return None;
    }
    sums.0 = smooth_slow(sums.0, units);
    sums.1 = smooth_slow(sums.1, seconds);
    Some(sums.1 / sums.0)
}

/// Slower smoothing for speed meters (about the last 20 batches), so one
/// preempted batch does not swing a rank's share.
pub fn smooth_slow(old: f64, new: f64) -> f64 {
    0.95 * old + 0.05 * new
}

/// Greedy assignment (SPEC 3.3, fig. 4.10): tasks sorted by cost, largest
/// first (ties by index, so the result is deterministic), each to the rank
/// whose finishing time (assigned + this task) / speed would be smallest.
/// `speeds[0]` is the coordinator, whose speed is scaled by
/// `coordinator_share` (< 1) so that it finishes first and is already waiting
/// when the replies arrive. Returns the rank slot of each task.
pub fn assign(costs: &[f64], speeds: &[f64], coordinator_share: f64) -> Vec<usize> {
    let effective: Vec<f64> = speeds
        .iter()
        .enumerate()
        .map(|(r, &s)| if r == 0 { s * coordinator_share } else { s }.max(1e-9))
        .collect();
    let mut order: Vec<usize> = (0..costs.len()).collect();
    order.sort_by(|&i, &j| costs[j].total_cmp(&costs[i]).then(i.cmp(&j)));
    let mut load = vec![0.0; speeds.len()];
    let mut slot = vec![0usize; costs.len()];
    for i in order {
        let mut best = 0;
        let mut best_finish = f64::INFINITY;
        for r in 0..speeds.len() {
            let finish = (load[r] + costs[i]) / effective[r];
            if finish < best_finish {
                best_finish = finish;
                best = r;
            }
        }
        load[best] += costs[i];
        slot[i] = best;
    }
    slot
}

/// A stage must be predicted this much faster distributed than alone before
/// it is distributed: estimates and latencies are noisy, and a stage that
/// flips between the two every frame gains nothing.
pub const DISTRIBUTE_MARGIN: f64 = 0.1;

/// How many workers a stage should use: 0 (rank 0 alone) or the k fastest.
///
/// Alone, the stage takes `estimated_s / speeds[0]`. With the k fastest
/// workers it takes its share of the work at their combined speed (rank 0
/// counted at `coordinator_share`), plus the messages: rank 0 posts k
/// requests one after another and waits for the last reply, about
/// (1 + k/2) round trips of `round_trip_s`. More workers divide the work
/// further but add messages, so beyond some k they cost more than they
/// save; the thesis's finding that one PC is faster below 15–20 bodies is
/// the k = 0 end of this. Ties go to fewer workers. Messages cost no time
/// for their size here; `workers_to_use_over_link` adds that.
pub fn workers_to_use(
    estimated_s: f64,
    speeds: &[f64],
    coordinator_share: f64,
    round_trip_s: f64,
) -> usize {
    workers_to_use_over_link(
        estimated_s,
        speeds,
        coordinator_share,
        round_trip_s,
        &Link::FREE,
    )
}

/// What the bytes of a stage's messages cost (SPEC 4: the thesis ran the
/// same scenes over 100BASE-T and 10BASE-T).
#[derive(Clone, Copy, Debug)]
pub struct Link {
    /// Bytes the stage's messages carried (requests and replies together)
    /// per second of estimated work handed to workers, as measured the last
    /// times the stage was distributed; 0 before it ever was.
    pub bytes_per_cost_s: f64,
    /// Rate of rank 0's link, bytes per second (measured at start-up).
    pub bytes_per_s: f64,
}

impl Link {
    pub const FREE: Link = Link {
        bytes_per_cost_s: 0.0,
        bytes_per_s: f64::INFINITY,
    };

    /// Seconds rank 0's link needs for the messages of a stage that hands
    /// `worker_cost_s` of work to workers. Every request and every reply
    /// passes through rank 0's one link, one after another, so they add
    /// (on a switched full-duplex link requests and replies could overlap;
    /// on the thesis's shared hubs they could not, and this counts them so).
    pub fn transfer_s(&self, worker_cost_s: f64) -> f64 {
        if self.bytes_per_s.is_finite() && self.bytes_per_s > 0.0 {
            self.bytes_per_cost_s * worker_cost_s / self.bytes_per_s
        } else {
            0.0
        }
    }
}

/// `workers_to_use`, with the time the stage's bytes take on rank 0's link:
/// with k workers, the part of the work they take (their share of the
/// combined speed) travels, at `link.bytes_per_cost_s` bytes per second of
/// work, through a link of `link.bytes_per_s`. Over 10 Mbit/s the bytes of
/// a small stage outweigh what its workers save, and it stays on rank 0.
pub fn workers_to_use_over_link(
    estimated_s: f64,
    speeds: &[f64],
    coordinator_share: f64,
    round_trip_s: f64,
    link: &Link,
) -> usize {
    let alone = estimated_s / speeds[0].max(1e-9);
    let mut workers: Vec<f64> = speeds[1..].to_vec();
    workers.sort_by(|a, b| b.total_cmp(a));
    let own = speeds[0] * coordinator_share;
    let mut combined = own;
    let (mut best, mut best_time) = (0, alone * (1.0 - DISTRIBUTE_MARGIN));
    for (k, s) in workers.iter().enumerate() {
        combined += s.max(0.0);
        let k = k + 1;
        let to_workers = estimated_s * (1.0 - own / combined.max(1e-9));
        let time = estimated_s / combined.max(1e-9)
            + round_trip_s * (1.0 + 0.5 * k as f64)
            + link.transfer_s(to_workers);
        if time < best_time {
            best = k;
            best_time = time;
        }
    }
    best
}

/// A stage stays on rank 0 for at most this many steps in a row, when the
/// cost model keeps it there, before one step is distributed anyway to
/// measure it again (`StageChoice`).
pub const PROBE_EVERY: u32 = 16;
/// The most steps between probes: each probe that leaves the distributed
/// steps measured slower doubles the wait up to this, as a probe of a
/// pile's split reruns its whole group (a step's work again).
pub const PROBE_EVERY_MOST: u32 = 256;
/// Weight of the newest step in the measured seconds per unit of cost.
const RATE_WEIGHT: f64 = 0.25;

/// Whether a self-scheduled stage (the group steps, the island solves)
/// goes to workers, from what it took: the cost model
/// (`workers_to_use_over_link`) adds the stage's bytes at the link rate
/// measured at start-up, and on shared memory that rate (64 KiB echoes) is
/// far below what a self-scheduled stage pays, whose sends overlap rank
/// 0's own share; with speeds that a meter over microsecond batches swings
/// by 2-10×, the 200-body pour on 2 ranks kept its groups on rank 0 in
/// half of its steps in some runs and in none in others (wall 1.68-1.75 s
/// against 1.48-1.50 s, the same state hash), and eight stacks of 15 boxes
/// kept their solves home in 97 % of the steps, two ranks taking 1.38 of
/// one rank's time. So where the model says "stay", the measured wall
/// seconds per unit of predicted cost of the steps that went out and of
/// those that stayed decide; a run of `PROBE_EVERY` steps kept home sends
/// one out, so the measure of the distributed steps stays current; each
/// step out that leaves them measured slower doubles that run, up to
/// `PROBE_EVERY_MOST`, and one that leaves them faster restores it. Where
/// the model says "go", it goes, as before. Only where the work is done
/// depends on this, never a result. The first step the model keeps home
/// is such a probe.
#[derive(Clone, Debug)]
pub struct StageChoice {
    /// Wall seconds per unit of predicted cost, smoothed (0: not measured).
    local_s_per_cost: f64,
    distributed_s_per_cost: f64,
    home_in_a_row: u32,
    /// Steps kept home before the next probe.
    probe_every: u32,
}

impl Default for StageChoice {
    fn default() -> Self {
        StageChoice {
            local_s_per_cost: 0.0,
            distributed_s_per_cost: 0.0,
            home_in_a_row: PROBE_EVERY,
            probe_every: PROBE_EVERY,
        }
    }
}

impl StageChoice {
    /// Workers for this step's stage: `modelled` where the model sends
    /// it out, else `workers` (the caller's choice of who would take
    /// them) where the distributed steps measured faster by
    /// `DISTRIBUTE_MARGIN` or a probe is due, else none.
    pub fn workers(&self, modelled: usize, workers: usize, tasks: usize) -> usize {
        if modelled > 0 || workers == 0 || tasks < 2 {
            return modelled;
        }
        if self.goes_out() { workers } else { 0 }
    }

    /// Whether the measures alone send the stage out now: it measured
    /// faster out by `DISTRIBUTE_MARGIN`, or a probe of it is due.
    pub fn goes_out(&self) -> bool {
        self.faster_out() || self.home_in_a_row >= self.probe_every
    }

    /// Whether the steps out measured faster than those home by
    /// `DISTRIBUTE_MARGIN`.
    fn faster_out(&self) -> bool {
        let (home, out) = (self.local_s_per_cost, self.distributed_s_per_cost);
        home > 0.0 && out > 0.0 && out < home * (1.0 - DISTRIBUTE_MARGIN)
    }

    /// Records a step's stage: whether it went out, its predicted cost and
    /// the wall seconds it took.
    pub fn record(&mut self, distributed: bool, cost: f64, wall_s: f64) {
        if distributed {
            self.home_in_a_row = 0;
        } else {
            self.home_in_a_row += 1;
        }
        if !(cost > 0.0 && wall_s.is_finite()) {
            return;
        }
        let rate = if distributed {
            &mut self.distributed_s_per_cost
        } else {
            &mut self.local_s_per_cost
        };
        let measured = wall_s / cost;
        *rate = if *rate > 0.0 {
            (1.0 - RATE_WEIGHT) * *rate + RATE_WEIGHT * measured
        } else {
            measured
        };
        if distributed && self.local_s_per_cost > 0.0 {
            self.probe_every = if self.faster_out() {
                PROBE_EVERY
            } else {
                (2 * self.probe_every).min(PROBE_EVERY_MOST)
            };
        }
    }
}

/// The slots of rank 0 and of the `k` fastest workers (ties to the lower
/// slot, so the choice is deterministic), as a mask over `speeds`.
pub fn fastest_slots(speeds: &[f64], k: usize) -> Vec<bool> {
    let mut order: Vec<usize> = (1..speeds.len()).collect();
    order.sort_by(|&i, &j| speeds[j].total_cmp(&speeds[i]).then(i.cmp(&j)));
    let mut used = vec![false; speeds.len()];
    used[0] = true;
    for &slot in order.iter().take(k) {
        used[slot] = true;
    }
    used
}

/// Finishing time of the slowest rank for an assignment (for tests and docs).
pub fn makespan(costs: &[f64], speeds: &[f64], slot: &[usize]) -> f64 {
    let mut load = vec![0.0; speeds.len()];
    for (i, &s) in slot.iter().enumerate() {
        load[s] += costs[i];
    }
    load.iter()
        .zip(speeds)
        .map(|(l, s)| l / s)
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn group_steps_go_out_where_they_measured_faster() {
        let mut choice = StageChoice::default();
        // The model sends them: they go, whatever was measured.
        assert_eq!(choice.workers(1, 1, 10), 1);
        // Nothing measured yet: the first "stay" is a probe.
        assert_eq!(choice.workers(0, 1, 10), 1);
        choice.record(true, 1e-3, 1e-3);
        // Home not measured yet: the model's "stay" holds.
        assert_eq!(choice.workers(0, 1, 10), 0);
        choice.record(false, 1e-3, 2e-3);
        // Out measured twice as fast as home: every worker.
        assert_eq!(choice.workers(0, 3, 10), 3);
        // Out measured slower than home: home, until the next probe, which
        // waits twice as long after each step out that measured slower.
        choice.record(true, 1e-3, 9e-3);
        choice.record(true, 1e-3, 9e-3);
        let wait = |choice: &mut StageChoice| {
            let mut home = 0;
            while choice.workers(0, 1, 10) == 0 {
                choice.record(false, 1e-3, 2e-3);
                home += 1;
                assert!(home <= PROBE_EVERY_MOST, "no probe");
            }
            home
        };
        assert_eq!(wait(&mut choice), 4 * PROBE_EVERY);
        choice.record(true, 1e-3, 9e-3);
        assert_eq!(wait(&mut choice), 8 * PROBE_EVERY);
        for _ in 0..8 {
            choice.record(true, 1e-3, 9e-3);
        }
        assert_eq!(wait(&mut choice), PROBE_EVERY_MOST);
        // A probe that measures out faster again: out, and probes as often
        // as at first once it is slower.
        for _ in 0..8 {
            choice.record(true, 1e-3, 1e-4);
        }
        assert_eq!(choice.workers(0, 1, 10), 1);
        choice.record(true, 1e-3, 1e-1);
        assert_eq!(wait(&mut choice), 2 * PROBE_EVERY);
        // One group, or no worker: home.
        assert_eq!(choice.workers(0, 1, 1), 0);
        assert_eq!(choice.workers(0, 0, 10), 0);
    }

    #[test]
    fn small_stages_stay_on_rank_0_and_large_ones_use_every_worker() {
        let speeds = [1.0, 1.0, 1.0, 1.0, 1.0];
        // 10 µs of work against 50 µs round trips: alone.
        assert_eq!(workers_to_use(1e-5, &speeds, 0.5, 5e-5), 0);
        // 1 s of work: messages are noise, use all four workers.
        assert_eq!(workers_to_use(1.0, &speeds, 0.5, 5e-5), 4);
        // 0.3 ms of work, 50 µs round trips: three workers (0.211 ms)
        // beat four (0.217 ms: the fourth's message costs more than its
        // share saves), two (0.220 ms) and rank 0 alone (0.3 ms).
        assert_eq!(workers_to_use(3e-4, &speeds, 0.5, 5e-5), 3);
        // No latency at all: every worker helps.
        assert_eq!(workers_to_use(1e-3, &speeds, 0.5, 0.0), 4);
    }

    #[test]
    fn a_much_slower_worker_is_left_out_and_the_fastest_are_chosen() {
        let speeds = [1.0, 0.01, 1.0, 1.0];
        let k = workers_to_use(1e-2, &speeds, 0.5, 1e-4);
        assert_eq!(k, 2, "the worker at 1 % speed adds messages, not speed");
        assert_eq!(fastest_slots(&speeds, k), vec![true, false, true, true]);
        // Ties go to the lower slot.
        assert_eq!(
            fastest_slots(&[1.0, 2.0, 2.0, 2.0], 2),
            vec![true, true, true, false]
        );
    }

    #[test]
    fn a_slow_link_keeps_a_stage_on_rank_0_that_a_fast_one_distributes() {
        let speeds = [1.0, 1.0, 1.0, 1.0];
        // 2 ms of work, 0.2 ms round trips; its messages carry 10⁸ bytes per
        // second of work (200 kB for the whole stage, about 170 kB of it to
        // the workers with all three).
        let bytes = 1e8;
        let link = |bytes_per_s| Link {
            bytes_per_cost_s: bytes,
            bytes_per_s,
        };
        let fast = link(12.5e6 * 1000.0);
        assert_eq!(workers_to_use_over_link(2e-3, &speeds, 0.5, 2e-4, &fast), 3);
        // 100 Mbit/s (12.5 MB/s): 170 kB take 14 ms, more than the stage
        // alone: rank 0 keeps it. So does 10 Mbit/s.
        let slow = link(12.5e6);
        assert_eq!(workers_to_use_over_link(2e-3, &speeds, 0.5, 2e-4, &slow), 0);
        assert_eq!(
            workers_to_use_over_link(2e-3, &speeds, 0.5, 2e-4, &link(1.25e6)),
            0
        );
        // A stage 100× larger per byte (1 s of work, the same bytes)
        // still pays at 10 Mbit/s.
        let lean = Link {
            bytes_per_cost_s: 2e5,
            bytes_per_s: 1.25e6,
        };
        assert_eq!(workers_to_use_over_link(1.0, &speeds, 0.5, 2e-4, &lean), 3);
        // Unmeasured bytes cost nothing: the plain rule.
        assert_eq!(
            workers_to_use_over_link(2e-3, &speeds, 0.5, 2e-4, &Link::FREE),
            workers_to_use(2e-3, &speeds, 0.5, 2e-4)
        );
    }

    #[test]
    fn distributing_needs_a_margin_over_working_alone() {
        // One equal worker, no latency: 1 / 1.5 of the time alone, a 33 %
        // gain, distributes; a worker so slow it gains under 10 % does not.
        assert_eq!(workers_to_use(1e-3, &[1.0, 1.0], 0.5, 0.0), 1);
        assert_eq!(workers_to_use(1e-3, &[1.0, 0.55], 0.5, 0.0), 0);
    }

    #[test]
    fn thesis_example_greedy_gives_13_75_seconds() {
        // SPEC 3.3: speeds 10 and 8, tasks 100, 60, 50: greedy 13.75 s (optimum 12.5 s).
        let costs = [100.0, 60.0, 50.0];
        let speeds = [10.0, 8.0];
        let slot = assign(&costs, &speeds, 1.0);
        assert!((makespan(&costs, &speeds, &slot) - 13.75).abs() < 1e-12);
    }

    #[test]
    fn slower_rank_gets_proportionally_less() {
        let costs = vec![1.0; 300];
        let speeds = [1.0, 1.0, 1.0 / 3.0];
        let slot = assign(&costs, &speeds, 1.0);
        let share = slot.iter().filter(|&&s| s == 2).count() as f64 / 300.0;
        // Speeds 1 : 1 : 1/3 → the slow rank's share is (1/3)/(7/3) = 1/7.
        assert!((share - 1.0 / 7.0).abs() < 0.01, "share {share}");
    }

    #[test]
    fn coordinator_is_given_less() {
        let costs = vec![1.0; 100];
        let slot = assign(&costs, &[1.0, 1.0], 0.5);
        let own = slot.iter().filter(|&&s| s == 0).count();
        assert!(own < 40, "rank 0 got {own} of 100");
    }
}

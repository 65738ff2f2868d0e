//! What the network costs rank 0's executor: the round trip and link rates
//! measured at start-up, each stage's bytes per second of work, and each
//! rank's host.

use super::MpiExecutor;
use super::protocol::Request as Req;
use super::schedule;
use std::time::Instant;

/// The stages whose messages are costed by their bytes (`schedule::Link`).
#[derive(Clone, Copy, Debug)]
pub(super) enum Stage {
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
pub(super) struct Network {
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
pub(super) struct TrafficMark {
    bytes: u64,
    worker_cost_s: f64,
    distributed: u64,
}

impl MpiExecutor<'_> {
    /// Each rank's host (`rank_hosts`), for messages and `summary.json`.
    pub fn set_hosts(&mut self, hosts: Vec<String>) {
        self.net.hosts = hosts;
    }

    pub(super) fn host_of(&self, rank: i32) -> &str {
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

    /// Median round trip of a tiny message to each worker.
    pub(super) fn measure_latency(&mut self) {
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

    /// Each worker's link rate: twice `PROBE_BYTES` over the time an echo
    /// of them takes beyond an empty echo, each the fastest of `PROBES`
    /// (interleaved). The fastest, not the median: on shared cores a
    /// sample's extra time is mostly the worker waiting for a core, which
    /// says nothing of the link. Their bytes are not booked (they are not
    /// the run's traffic).
    pub(super) fn measure_link_rates(&mut self) {
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
    pub(super) fn workers_for_stage(
        &self,
        stage: Stage,
        estimated_s: f64,
        tasks: usize,
        share: f64,
    ) -> usize {
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

    pub(super) fn traffic_mark(&self, stage: Stage) -> TrafficMark {
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
    pub(super) fn learn_traffic(&mut self, stage: Stage, mark: TrafficMark) {
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

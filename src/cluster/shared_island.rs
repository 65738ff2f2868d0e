//! One large island shared by the ranks (`contact::block_sweeps`): rank 0
//! solves it, and at each exchange of its sweeps hands each worker the
//! state of the blocks it sweeps, sweeps its own, and takes the workers'
//! back in block order. The blocks go to the ranks by the greedy rule and
//! the measured speeds once a solve (the first exchange carries their
//! systems); where a block is swept changes no bit of the answer.

use super::MpiExecutor;
use super::protocol::{Reply, Request as Req};
use super::schedule;
use crate::contact::block_sweeps::{BlockRunner, SweptBlocks};
use mpi::topology::Communicator;
use std::time::Instant;

/// Rank 0's `BlockRunner` over every worker.
pub(super) struct SharedBlocks<'e, 'w> {
    exec: &'e mut MpiExecutor<'w>,
    /// Per slot (0: rank 0), the blocks it sweeps in this solve.
    plan: Vec<Vec<usize>>,
    /// A round of the island's was shared already (its phases each sweep).
    shared: bool,
}

impl<'e, 'w> SharedBlocks<'e, 'w> {
    pub(super) fn new(exec: &'e mut MpiExecutor<'w>) -> Self {
        SharedBlocks {
            exec,
            plan: Vec::new(),
            shared: false,
        }
    }

    /// The blocks per slot by the greedy rule and each slot's measured
    /// speed at sweeping blocks (all alike until measured). Rank 0 takes
    /// a full share: the rows between blocks wait for every block.
    fn plan(&self, rows: &[usize]) -> Vec<Vec<usize>> {
        let speeds: Vec<f64> = self
            .exec
            .block_meters
            .iter()
            .map(|m| m.speed())
            .map(|s| if s.is_finite() && s > 0.0 { s } else { 1.0 })
            .collect();
        let costs: Vec<f64> = rows.iter().map(|&r| r as f64).collect();
        let mut plan = vec![Vec::new(); speeds.len()];
        for (k, slot) in schedule::assign(&costs, &speeds, 1.0)
            .into_iter()
            .enumerate()
        {
            plan[slot].push(k);
        }
        plan
    }

    /// Notes that slot `slot` swept `rows` rows `sweeps` times in `busy_s`.
    fn meter(&mut self, slot: usize, rows: usize, sweeps: usize, busy_s: f64) {
        self.exec.book[slot].block_rows += (rows * sweeps) as u64;
        if rows > 0 && busy_s > 0.0 {
            self.exec.block_meters[slot].add((rows * sweeps) as f64, busy_s);
        }
    }

    /// Sends each worker its blocks' states (and, at the first round,
    /// their systems) for `sweeps` sweeps.
    fn hand_out(&mut self, blocks: &SweptBlocks, sweeps: usize) {
        for (slot, mine) in self.plan.iter().enumerate().skip(1) {
            if mine.is_empty() {
                continue;
            }
            let open = blocks
                .first
                .then(|| mine.iter().map(|&k| blocks.system_of(k)).collect());
            let states = mine.iter().map(|&k| blocks.state_of(k)).collect();
            let rank = self.exec.roles.workers[slot - 1];
            self.exec.send(
                rank,
                &Req::SweepBlocks {
                    open,
                    states,
                    sweeps: sweeps as u32,
                },
            );
        }
    }

    /// Takes each worker's swept blocks back, in slot order, metering it
    /// on `rows` (each block's).
    fn gather(&mut self, blocks: &mut SweptBlocks, sweeps: usize, rows: &[usize]) {
        for slot in 1..self.plan.len() {
            let mine = std::mem::take(&mut self.plan[slot]);
            if mine.is_empty() {
                continue;
            }
            let rank = self.exec.roles.workers[slot - 1];
            let states = match self.exec.receive(rank) {
                Reply::SweepBlocks { states, busy_s } if states.len() == mine.len() => {
                    self.exec.book[slot].busy_s += busy_s;
                    let swept = mine.iter().map(|&k| rows[k]).sum();
                    self.meter(slot, swept, sweeps, busy_s);
                    states
                }
                _ => {
                    eprintln!("rigidsim: rank 0: rank {rank} answered a block sweep wrongly");
                    self.exec.world.abort(4)
                }
            };
            for (&k, state) in mine.iter().zip(&states) {
                blocks.set_state(k, state);
            }
            self.plan[slot] = mine;
        }
    }
}

impl BlockRunner for SharedBlocks<'_, '_> {
    fn sweep_blocks(&mut self, blocks: &mut SweptBlocks, sweeps: usize) {
        let rows: Vec<usize> = (0..blocks.blocks.len())
            .map(|k| blocks.blocks.rows(k))
            .collect();
        if blocks.first {
            self.plan = self.plan(&rows);
        }
        if !self.shared {
            self.shared = true;
            self.exec.dist.islands_shared += 1;
        }
        self.hand_out(blocks, sweeps);
        let clock = Instant::now();
        for &k in &self.plan[0] {
            blocks.sweep_here(k, sweeps);
        }
        let own = self.plan[0].iter().map(|&k| rows[k]).sum();
        self.meter(0, own, sweeps, clock.elapsed().as_secs_f64());
        self.gather(blocks, sweeps, &rows);
        self.exec.dist.block_exchanges += 1;
    }
}

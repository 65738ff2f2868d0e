//! The large-island method's sweeps by blocks, so that ranks can share one
//! island. The island's moving bodies are cut into blocks by where they are
//! (`IslandBlocks::cut`: halved along the widest extent, again and again, a
//! rule of the island alone), and each sweep takes every block's own rows
//! (those that move only its bodies, and fixed ones) and then the rows
//! between blocks. A block's rows touch no other block's bodies or
//! impulses, so the blocks commute: swept in any order, on any rank, they
//! give the same bits, and one rank sweeping them all in turn
//! (`InlineBlocks`) gives what many do (`BlockRunner`).
//!
//! The rows are the plain sweep's in another order, so the answers differ
//! from the whole island's sweeps by what a sweep's order changes (the
//! method's checks and budget are the same, `pile_sweeps`).

use crate::contact::system::{IterativeState, IterativeSystem, Row};
use crate::contact::task::IslandBody;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// How the large-island method sweeps by blocks.
#[derive(Clone, Copy, Debug)]
pub struct BlockSweepSettings {
    /// Sweeps of the blocks' own rows between sweeps of the rows between
    /// blocks (each a round of messages where ranks share the island; 1
    /// would keep the sweep a Gauss–Seidel sweep of every row): a check's
    /// worth (`PileSweepSettings::check_every`), as a round of messages
    /// costs more than a block's sweep.
    pub exchange_every: usize,
}

impl Default for BlockSweepSettings {
    fn default() -> Self {
        BlockSweepSettings { exchange_every: 10 }
    }
}

/// An island's rows cut into blocks of its moving bodies, and the rows
/// between blocks.
pub struct IslandBlocks {
    blocks: Vec<Block>,
    /// Rows between two blocks, in row order (swept after the blocks).
    between: Vec<usize>,
}

/// One block: its own rows in row order, and the bodies they touch (its
/// moving bodies and any fixed ones), ascending.
struct Block {
    rows: Vec<usize>,
    bodies: Vec<usize>,
}

impl IslandBlocks {
    /// `rows` of an island of `bodies`, cut into `count` blocks (fewer where
    /// the island has fewer moving bodies).
    pub(in crate::contact) fn cut(
        bodies: &[IslandBody],
        rows: &[Row],
        count: usize,
    ) -> IslandBlocks {
        let mut moving: Vec<usize> = (0..bodies.len())
            .filter(|&i| bodies[i].inv_mass > 0.0)
            .collect();
        let count = count.clamp(1, moving.len().max(1));
        let mut block_of = vec![None; bodies.len()];
        bisect(bodies, &mut moving, count, 0, &mut block_of);
        let mut blocks: Vec<Block> = (0..count)
            .map(|_| Block {
                rows: Vec::new(),
                bodies: Vec::new(),
            })
            .collect();
        let mut between = Vec::new();
        for (i, row) in rows.iter().enumerate() {
            match (block_of[row.a], block_of[row.b]) {
                (Some(x), Some(y)) if x != y => between.push(i),
                (Some(x), _) | (None, Some(x)) => blocks[x].rows.push(i),
                (None, None) => between.push(i),
            }
        }
        for block in &mut blocks {
            block.bodies = block
                .rows
                .iter()
                .flat_map(|&i| [rows[i].a, rows[i].b])
                .collect();
            block.bodies.sort_unstable();
            block.bodies.dedup();
        }
        IslandBlocks { blocks, between }
    }

    /// Blocks (some may have no rows).
    pub fn len(&self) -> usize {
        self.blocks.len()
    }

    pub fn is_empty(&self) -> bool {
        self.blocks.is_empty()
    }

    /// Block k's rows: what a sweep of it costs.
    pub fn rows(&self, k: usize) -> usize {
        self.blocks[k].rows.len()
    }
}

/// Places `members` (moving bodies) in blocks `first..first + count`:
/// sorted along their widest extent (ties by index) and halved by count,
/// again and again.
fn bisect(
    bodies: &[IslandBody],
    members: &mut [usize],
    count: usize,
    first: usize,
    block_of: &mut [Option<usize>],
) {
    if count <= 1 || members.len() <= 1 {
        for &i in members.iter() {
            block_of[i] = Some(first);
        }
        return;
    }
    let axis = widest_axis(bodies, members);
    members.sort_by(|&i, &j| {
        bodies[i].position[axis]
            .total_cmp(&bodies[j].position[axis])
            .then(i.cmp(&j))
    });
    let left = count / 2;
    let cut = members.len() * left / count;
    let (low, high) = members.split_at_mut(cut);
    bisect(bodies, low, left, first, block_of);
    bisect(bodies, high, count - left, first + left, block_of);
}

/// The axis along which `members`' positions spread widest (the lowest
/// of equals).
fn widest_axis(bodies: &[IslandBody], members: &[usize]) -> usize {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for &i in members {
        lo = lo.inf(&bodies[i].position);
        hi = hi.sup(&bodies[i].position);
    }
    let extent = hi - lo;
    (0..3).fold(0, |best, k| if extent[k] > extent[best] { k } else { best })
}

/// One block's rows as a system of its own, numbered within the block:
/// what a rank that sweeps the block is sent once a solve.
#[derive(Clone, Serialize, Deserialize)]
pub struct BlockSystem {
    rows: Vec<Row>,
    diag: Vec<f64>,
    b: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    findex: Vec<Option<usize>>,
    compliance: f64,
}

/// One block's impulses and its bodies' velocity changes, numbered within
/// the block: what travels each exchange.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct BlockState(IterativeState);

impl std::fmt::Debug for BlockSystem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "BlockSystem {{ {} rows }}", self.rows.len())
    }
}

impl BlockSystem {
    /// `sweeps` sweeps of the block's rows on `state`.
    pub fn sweep(&self, state: &mut BlockState, sweeps: usize) {
        let system = IterativeSystem {
            rows: &self.rows,
            diag: &self.diag,
            b: &self.b,
            lo: &self.lo,
            hi: &self.hi,
            findex: &self.findex,
            compliance: self.compliance,
            tolerance: 0.0,
        };
        for _ in 0..sweeps {
            system.sweep(&mut state.0);
        }
    }
}

/// The blocks of one solve, its system and its state, as a `BlockRunner`
/// sees them.
pub struct SweptBlocks<'s, 'a> {
    pub blocks: &'s IslandBlocks,
    system: &'s IterativeSystem<'a>,
    state: &'s mut IterativeState,
    /// The solve's first exchange: the blocks' systems are new.
    pub first: bool,
}

impl SweptBlocks<'_, '_> {
    /// Block k as a system of its own.
    pub fn system_of(&self, k: usize) -> BlockSystem {
        let block = &self.blocks.blocks[k];
        let local = |body: usize| {
            block
                .bodies
                .binary_search(&body)
                .expect("a block's rows touch only its bodies")
        };
        let s = self.system;
        let row_in_block = |i: usize| {
            block
                .rows
                .binary_search(&i)
                .expect("a friction row is in its normal row's block")
        };
        BlockSystem {
            rows: block
                .rows
                .iter()
                .map(|&i| s.rows[i].renumbered(local(s.rows[i].a), local(s.rows[i].b)))
                .collect(),
            diag: block.rows.iter().map(|&i| s.diag[i]).collect(),
            b: block.rows.iter().map(|&i| s.b[i]).collect(),
            lo: block.rows.iter().map(|&i| s.lo[i]).collect(),
            hi: block.rows.iter().map(|&i| s.hi[i]).collect(),
            findex: block
                .rows
                .iter()
                .map(|&i| s.findex[i].map(row_in_block))
                .collect(),
            compliance: s.compliance,
        }
    }

    /// Block k's impulses and velocity changes now.
    pub fn state_of(&self, k: usize) -> BlockState {
        let block = &self.blocks.blocks[k];
        BlockState(IterativeState {
            p: block.rows.iter().map(|&i| self.state.p[i]).collect(),
            dv: block.bodies.iter().map(|&j| self.state.dv[j]).collect(),
            dw: block.bodies.iter().map(|&j| self.state.dw[j]).collect(),
        })
    }

    /// Block k's impulses and velocity changes as a rank swept them.
    pub fn set_state(&mut self, k: usize, swept: &BlockState) {
        let block = &self.blocks.blocks[k];
        let swept = &swept.0;
        for (&i, &p) in block.rows.iter().zip(&swept.p) {
            self.state.p[i] = p;
        }
        for (n, &j) in block.bodies.iter().enumerate() {
            self.state.dv[j] = swept.dv[n];
            self.state.dw[j] = swept.dw[n];
        }
    }

    /// `sweeps` sweeps of block k's rows, here.
    pub fn sweep_here(&mut self, k: usize, sweeps: usize) {
        for _ in 0..sweeps {
            self.system
                .sweep_rows(&self.blocks.blocks[k].rows, self.state);
        }
    }
}

/// Who sweeps the blocks: every block `sweeps` times on the state, in any
/// order and on any ranks (they commute).
pub trait BlockRunner {
    fn sweep_blocks(&mut self, blocks: &mut SweptBlocks, sweeps: usize);
}

/// Every block in turn, here.
pub struct InlineBlocks;

impl BlockRunner for InlineBlocks {
    fn sweep_blocks(&mut self, blocks: &mut SweptBlocks, sweeps: usize) {
        for k in 0..blocks.blocks.len() {
            blocks.sweep_here(k, sweeps);
        }
    }
}

/// One solve's sweeps by blocks: the island's blocks, who sweeps them,
/// and how often they meet the rows between blocks.
pub(in crate::contact) struct BlockSweeps<'r> {
    blocks: IslandBlocks,
    runner: &'r mut dyn BlockRunner,
    settings: BlockSweepSettings,
    /// No exchange made yet (the runner hands the blocks out at the first).
    first: bool,
}

impl<'r> BlockSweeps<'r> {
    pub fn new(
        blocks: IslandBlocks,
        runner: &'r mut dyn BlockRunner,
        settings: BlockSweepSettings,
    ) -> Self {
        BlockSweeps {
            blocks,
            runner,
            settings,
            first: true,
        }
    }

    /// `sweeps` sweeps of `system`: rounds of `exchange_every` sweeps of
    /// the blocks' own rows (by the runner), each followed by as many of
    /// the rows between blocks.
    pub(in crate::contact) fn sweep(
        &mut self,
        system: &IterativeSystem,
        state: &mut IterativeState,
        sweeps: usize,
    ) {
        let mut left = sweeps;
        while left > 0 {
            let round = left.min(self.settings.exchange_every.max(1));
            self.runner.sweep_blocks(
                &mut SweptBlocks {
                    blocks: &self.blocks,
                    system,
                    state,
                    first: self.first,
                },
                round,
            );
            self.first = false;
            for _ in 0..round {
                system.sweep_rows(&self.blocks.between, state);
            }
            left -= round;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyId;
    use crate::contact::methods::pile_sweeps::{self, PileSweepSettings, Sweeping};
    use crate::contact::system::{Phase, PhaseSystem};
    use crate::contact::task::{IslandContact, IslandTask, fixed_body, resting_contact};
    use nalgebra::Matrix3;

    /// A 1 kg unit cube at (x, y, ½) falling at 0.1 m/s.
    fn cube(x: f64, y: f64) -> IslandBody {
        IslandBody {
            id: BodyId(1),
            inv_mass: 1.0,
            inv_inertia: Matrix3::identity() * 6.0,
            position: Vector3::new(x, y, 0.5),
            velocity: Vector3::new(0.0, 0.0, -0.1),
            external_dv: Vector3::new(0.0, 0.0, -0.0981),
            ..fixed_body(Vector3::zeros())
        }
    }

    fn contact(a: usize, b: usize, point: Vector3<f64>, normal: Vector3<f64>) -> IslandContact {
        resting_contact(a, b, point, normal, 0.5)
    }

    /// An `n`×`n` layer of unit cubes side by side on a fixed floor (body
    /// 0): four corner contacts each on the floor and with its neighbour
    /// along x and along y.
    fn layer(n: usize) -> IslandTask {
        let mut bodies = vec![fixed_body(Vector3::zeros())];
        let at = |i: usize, j: usize| 1 + i * n + j;
        for i in 0..n {
            for j in 0..n {
                bodies.push(cube(i as f64, j as f64));
            }
        }
        let mut contacts = Vec::new();
        let corners = [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)];
        for i in 0..n {
            for j in 0..n {
                let (x, y) = (i as f64, j as f64);
                for &(u, v) in &corners {
                    let p = Vector3::new(x + u, y + v, 0.0);
                    contacts.push(contact(at(i, j), 0, p, Vector3::z()));
                }
                for &(u, v) in &corners {
                    if i + 1 < n {
                        let p = Vector3::new(x + 0.5, y + 0.5 * u, 0.5 + v);
                        contacts.push(contact(at(i + 1, j), at(i, j), p, Vector3::x()));
                    }
                    if j + 1 < n {
                        let p = Vector3::new(x + 0.5 * u, y + 0.5, 0.5 + v);
                        contacts.push(contact(at(i, j + 1), at(i, j), p, Vector3::y()));
                    }
                }
            }
        }
        IslandTask {
            bodies,
            contacts,
            dt: 0.01,
            restitution_threshold: 0.049,
            iterative_min_rows: 0,
            island_blocks: 4,
        }
    }

    fn impact_system(task: &IslandTask) -> PhaseSystem {
        let v: Vec<_> = task.bodies.iter().map(|b| b.velocity).collect();
        let w: Vec<_> = task.bodies.iter().map(|b| b.angular_velocity).collect();
        PhaseSystem::build(task, &v, &w, Phase::Impact)
    }

    /// Every row is one block's or between blocks; a block's rows touch
    /// its bodies alone and move no other block's; the blocks split the
    /// moving bodies about evenly.
    #[test]
    fn every_row_is_one_blocks_or_between_and_blocks_share_no_moving_body() {
        let task = layer(8);
        let system = impact_system(&task);
        let blocks = IslandBlocks::cut(&task.bodies, &system.rows, 4);
        assert_eq!(blocks.len(), 4);
        let mut seen = vec![0; system.rows.len()];
        let mut owner = vec![None; task.bodies.len()];
        for (k, block) in blocks.blocks.iter().enumerate() {
            for &i in &block.rows {
                seen[i] += 1;
                for body in [system.rows[i].a, system.rows[i].b] {
                    assert!(block.bodies.contains(&body));
                    if task.bodies[body].inv_mass > 0.0 {
                        assert!(
                            owner[body].is_none_or(|o| o == k),
                            "body {body} in two blocks"
                        );
                        owner[body] = Some(k);
                    }
                }
            }
        }
        for &i in &blocks.between {
            seen[i] += 1;
        }
        assert!(seen.iter().all(|&n| n == 1), "a row in no block or in two");
        let moving: Vec<usize> = (0..4)
            .map(|k| owner.iter().filter(|&&o| o == Some(k)).count())
            .collect();
        assert_eq!(moving, vec![16; 4], "an 8×8 layer halved twice");
        assert!(!blocks.between.is_empty() && blocks.between.len() < system.rows.len() / 4);
    }

    /// Sweeps block by block in reverse order, or through each block's own
    /// system and state as a worker sweeps them, give the very bits of
    /// sweeping them in turn here: the blocks commute.
    #[test]
    fn blocks_swept_in_any_order_or_elsewhere_give_the_same_bits() {
        struct Reversed;
        impl BlockRunner for Reversed {
            fn sweep_blocks(&mut self, blocks: &mut SweptBlocks, sweeps: usize) {
                for k in (0..blocks.blocks.len()).rev() {
                    blocks.sweep_here(k, sweeps);
                }
            }
        }
        /// As `shared_island` does: each block's system sent at the first
        /// exchange, its state every exchange.
        struct Elsewhere(Vec<BlockSystem>);
        impl BlockRunner for Elsewhere {
            fn sweep_blocks(&mut self, blocks: &mut SweptBlocks, sweeps: usize) {
                if blocks.first {
                    self.0 = (0..blocks.blocks.len())
                        .map(|k| blocks.system_of(k))
                        .collect();
                }
                for k in 0..blocks.blocks.len() {
                    let mut state = blocks.state_of(k);
                    self.0[k].sweep(&mut state, sweeps);
                    blocks.set_state(k, &state);
                }
            }
        }
        let task = layer(8);
        let system = impact_system(&task);
        let iterative = system.iterative();
        let settings = PileSweepSettings::default();
        let solve = |runner: &mut dyn BlockRunner| {
            let sweeping = Sweeping::Blocks(BlockSweeps::new(
                IslandBlocks::cut(&task.bodies, &system.rows, 4),
                runner,
                BlockSweepSettings::default(),
            ));
            pile_sweeps::solve(
                &iterative,
                &system.warm,
                task.bodies.len(),
                &settings,
                sweeping,
            )
        };
        let inline = solve(&mut InlineBlocks);
        assert!(inline.sweeps > 0, "solved before any sweep");
        let bits = |p: &[f64]| p.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for answer in [solve(&mut Reversed), solve(&mut Elsewhere(Vec::new()))] {
            assert_eq!(answer.sweeps, inline.sweeps);
            assert_eq!(bits(&answer.p), bits(&inline.p));
        }
    }

    /// By blocks the method stops the falling layer as it does swept
    /// whole: every cube at rest after the impact to the method's
    /// tolerance, the floor's impulse its momentum, 0.1 N·s a cube.
    #[test]
    fn by_blocks_the_layer_stops_as_swept_whole() {
        let task = layer(8);
        let system = impact_system(&task);
        let iterative = system.iterative();
        let settings = PileSweepSettings::default();
        let cut = IslandBlocks::cut(&task.bodies, &system.rows, 4);
        let mut inline = InlineBlocks;
        let sweeping = Sweeping::Blocks(BlockSweeps::new(
            cut,
            &mut inline,
            BlockSweepSettings::default(),
        ));
        let by_blocks = pile_sweeps::solve(
            &iterative,
            &system.warm,
            task.bodies.len(),
            &settings,
            sweeping,
        );
        let whole = pile_sweeps::solve(
            &iterative,
            &system.warm,
            task.bodies.len(),
            &settings,
            Sweeping::Whole,
        );
        for answer in [&by_blocks, &whole] {
            assert!(
                answer.met,
                "missed the conditions in {} sweeps",
                answer.sweeps
            );
            let mut v: Vec<Vector3<f64>> = task.bodies.iter().map(|b| b.velocity).collect();
            let mut w = vec![Vector3::zeros(); task.bodies.len()];
            for (row, &p) in system.rows.iter().zip(&answer.p) {
                row.change_velocities(p, &mut v, &mut w);
            }
            for (i, (v, w)) in v.iter().zip(&w).enumerate().skip(1) {
                assert!(
                    v.norm() < 1e-7 && w.norm() < 1e-7,
                    "cube {i}: v {v:?}, w {w:?}"
                );
            }
            let floor: f64 = system
                .rows
                .iter()
                .zip(&answer.p)
                .filter(|(r, _)| r.b == 0 && r.lin == Vector3::z())
                .map(|(_, p)| p)
                .sum();
            assert!((floor - 6.4).abs() < 1e-6, "floor impulse {floor}");
        }
    }
}

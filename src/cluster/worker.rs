//! A worker rank's loop.

use super::protocol::{self, Reply, Request as Req, WorkerReport, decode, encode};
use super::speed::{stall, thread_cpu_time};
use crate::collision::narrowphase;
use crate::contact::block_sweeps::BlockSystem;
use crate::contact::solver;
use crate::output::capture;
use crate::scene::Scene;
use crate::step::{GroupReply, Inline, PreparedPairs, prepare_pairs, run_group};
use mpi::point_to_point::{Destination, Source};
use mpi::topology::{Communicator, SimpleCommunicator};
use std::time::{Duration, Instant};

/// A worker rank: answers requests from rank 0 until `Stop`.
pub fn worker_loop(world: &SimpleCommunicator, scene: &Scene, slow: f64) {
    let root = world.process_at_rank(0);
    let mut report = WorkerReport::default();
    // The scene with the forces rank 0 last shared (`Req::Forces`), once it
    // has shared any.
    let mut shared: Option<Scene> = None;
    // The blocks of the island being shared (`Req::SweepBlocks`).
    let mut blocks: Vec<BlockSystem> = Vec::new();
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
                    // `--capture-islands`: written where they were built
                    // (they do not travel with the reply).
                    capture::islands(&r.1);
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
            Req::SweepBlocks {
                open,
                mut states,
                sweeps,
            } => {
                if let Some(open) = open {
                    blocks = open;
                }
                if states.len() != blocks.len() {
                    eprintln!(
                        "rigidsim: rank {}: {} block states for {} blocks",
                        world.rank(),
                        states.len(),
                        blocks.len()
                    );
                    world.abort(4);
                }
                for (block, state) in blocks.iter().zip(&mut states) {
                    block.sweep(state, sweeps as usize);
                }
                let busy = stall(slow, clock, cpu).as_secs_f64();
                report.busy_s += busy;
                Reply::SweepBlocks {
                    states,
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

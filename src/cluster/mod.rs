//! Everything MPI (SPEC 3): rank roles, the coordinator's executor that
//! scatters exact collision and Dantzig solves over workers, the worker loop,
//! and the render rank.
//!
//! Roles: rank 0 coordinates (and does its own, smaller share); ranks 1 … N−2
//! are workers; the last rank renders when the scene has a `[render]` section
//! and `--no-render` is not given, otherwise it is a worker too. One rank runs
//! the same stages inline.

pub mod predict;
pub mod protocol;
pub mod schedule;

mod executor;
mod hosts;
mod messages;
mod network;
mod polled;
mod prepare;
mod render_rank;
mod scatter;
mod shared_island;
mod speed;
mod stages;
mod worker;

pub use executor::MpiExecutor;
pub use hosts::{
    hostname, hosts_line, mixed_vector_units_line, rank_hosts, rank_vector_units, vector_units,
};
pub use render_rank::{RENDER_QUEUE, RemoteFrames, renderer_loop};
pub use speed::slow_factor;
pub use worker::worker_loop;

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

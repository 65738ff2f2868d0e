//! rigidsim: rigid-body dynamics over an MPI cluster of lab PCs.
//!
//! The pipeline, one folder a stage: `scene` (loading), `body` (state and mass
//! properties), `collision` (broadphase, V-Clip, contact points), `contact`
//! (islands, Dantzig LCP), `dynamics` (integration), `step` (the frame loop),
//! `cluster` (everything MPI), `render` (off-screen frames), `output`
//! (trajectory, summary, progress), `export` (a scene as JSON for other tools),
//! `math` (sines with the same bits on every host), `polyhedron` (convex
//! shapes, below `body` and `collision`).

pub mod body;
pub mod cluster;
pub mod collision;
pub mod contact;
pub mod dynamics;
pub mod export;
pub mod interrupt;
pub mod math;
pub mod output;
pub mod polyhedron;
pub mod render;
pub mod run;
pub mod scene;
pub mod step;

//! Contact systems and their impulses and forces (SPEC 2.4): islands, the
//! LCP rows of an island, and Dantzig's algorithm. No MPI in here.

mod block_lu;
mod interior;
pub mod island;
pub mod lcp;
mod pile_sweeps;
pub mod solver;
mod subspace;
mod system;

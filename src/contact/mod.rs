//! Contact systems and their impulses and forces (SPEC 2.4): islands, the
//! island's request and reply (`task`), the LCP rows of an island
//! (`system`), the methods that solve them (`methods`, Dantzig's algorithm
//! among them), the order they are tried in (`policy`, `chain`), and the
//! checks of an answer (`guard`). No MPI in here.

mod chain;
mod guard;
pub mod island;
mod methods;
mod policy;
mod restitution;
pub mod solver;
mod system;
mod task;

pub use methods::block_sweeps;
pub use methods::lcp;

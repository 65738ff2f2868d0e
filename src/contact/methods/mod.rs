//! The methods that solve a contact system (`contact::system`), one file
//! each: Dantzig's method (`lcp`; on an island's dense system,
//! `dantzig`), the sweeps (`sweeps`) and the subspace step they take
//! (`subspace`), the interior point (`interior`, with its block
//! factorisation `block_lu`) and the large-island method (`pile_sweeps`,
//! which may sweep by blocks that ranks share, `block_sweeps`).
//! Which of them answers is the policy's (`contact::policy`).

mod block_lu;
pub mod block_sweeps;
pub(crate) mod dantzig;
pub(crate) mod interior;
pub mod lcp;
pub(crate) mod pile_sweeps;
mod subspace;
pub(crate) mod sweeps;

//! Collision (SPEC 2.3, 2.6): bounding-sphere broadphase, V-Clip exact
//! distance on convex parts, contact points. Pure functions over plain data:
//! no MPI in here, so worker ranks run the very same calls.

pub mod broadphase;
pub mod manifold;
pub mod narrowphase;
pub mod patch;
pub mod sat;
pub mod vclip;

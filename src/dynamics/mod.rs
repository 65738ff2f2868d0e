//! Dynamics: integration, the contact phase and the world step.

pub mod integrate;

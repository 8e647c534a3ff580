//! The method checked against the paper, exact answers and its own
//! readers, one test binary.

#[allow(dead_code)]
mod adaptive;
mod adaptive_lattice;
mod common;

mod carfollow_adaptive;
mod carfollow_library;
mod cutin_paper;
mod external_protocol;
mod gap_seeker_ceiling;
mod highway_geometry;
mod island;
mod paired;
mod readers_fuzz;
mod sampling_exact;

//! The testing-scenario-library method of Feng et al. (2020), pure and
//! synchronous: grids and exposure models, vehicle models, the cases, library
//! search, sampling, estimation and exact answers. No I/O beyond parsing text
//! handed in, no async, no HTTP: usable alone from a program or a benchmark.

pub mod adaptive;
pub mod alias;
pub mod campaign;
pub mod case;
pub mod cases;
pub mod density;
pub mod descriptor;
pub mod estimator;
pub mod exact;
pub mod external;
pub mod grid;
pub mod library;
pub mod long_table;
pub mod mass;
pub mod ndd_table;
pub mod number;
pub mod objective;
pub mod openscenario;
pub mod outside;
pub mod paired;
pub mod prefix;
pub mod progress;
pub mod registry;
pub mod sampling;
pub mod test_stream;
pub mod tolerance;
pub mod vehicle;
pub mod warnings;

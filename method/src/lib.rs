//! The testing-scenario-library method of Feng et al. (2020), pure and
//! synchronous: grids and exposure models, vehicle models, the cases, library
//! search, sampling, estimation and exact answers. No I/O beyond parsing text
//! handed in, no async, no HTTP: usable alone from a program or a benchmark.
//!
//! # Layout
//!
//! Modules by concept, from the foundations up. No two files import each
//! other, directly or around a loop (`tests/it/architecture.rs`); a
//! concept's files may use a later group's where the method does (a
//! library search runs a case's simulation).
//!
//! Numbers, grids and exposure:
//! - `number`: numbers as messages print them; `tolerance`: the tolerances,
//!   named once.
//! - `grid`: scenario grids; `mass`: probability mass on a grid;
//!   `density`: exposure models as densities.
//! - `ndd_table`, `long_table`: exposure tables in the authors' and the
//!   long layout.
//! - `test_stream`: each test's random stream; `alias`: exact draws by
//!   alias tables.
//! - `progress`: counting long work for a progress bar.
//!
//! Vehicles and simulation:
//! - `vehicle`: the car-following models (IDM, FVDM, switching ACC,
//!   ACC+AEB) and their parameters.
//! - `external`: a vehicle under test that is a program (the JSON-lines
//!   protocol).
//! - `case`: what a grid case is to the method (the `Case` trait);
//!   `objective`: the surrogate search's objective; `openscenario`: a
//!   scenario as OpenSCENARIO.
//!
//! Statistics:
//! - `estimator`: the importance-sampling estimator and stopping rule;
//!   `prefix`: folding results in test order; `outside`: the bound on the
//!   failure mass outside a library.
//! - `sequence`: confidence sequences by betting; `anytime`: a campaign's
//!   interval that holds at every number of tests.
//! - `paired`: paired regressions; `exact`: exact answers by enumeration;
//!   `guard_floor`: the fewest tests a guarded campaign of a noisy vehicle
//!   can expect, were every cell's rate known;
//!   `warnings`: what an answer's numbers warn of; `noise`: the noise of a
//!   vehicle that is not bit-reproducible.
//! - `discordance`: whether a worker's program behaves like the others'
//!   (an e-value of discordant pairs); `test_pairing`: each worker's tests
//!   paired with the fleet's, so that every test is such evidence.
//!
//! The method:
//! - `library`: scenario libraries and their search.
//! - `sampling`: the test distributions (library, NDD, an adaptive
//!   stage's support).
//! - `campaign`: a campaign run in this process; `adaptive`: campaigns
//!   that learn where the vehicle fails, in stages.
//!
//! Cases, for a service:
//! - `descriptor`: what the service and the command line know of a case;
//!   `cases`: cut-in, highway exit, car-following and user-defined cases;
//!   `registry`: every case behind one interface (`ScenarioCase` and the
//!   traits it is split into, `CampaignTests`).

pub mod adaptive;
pub mod alias;
pub mod anytime;
pub mod campaign;
pub mod case;
pub mod cases;
pub mod density;
pub mod descriptor;
pub mod discordance;
pub mod estimator;
pub mod exact;
pub mod external;
pub mod grid;
pub mod guard_floor;
pub mod library;
pub mod long_table;
pub mod mass;
pub mod ndd_table;
pub mod noise;
pub mod number;
pub mod objective;
pub mod openscenario;
pub mod outside;
pub mod paired;
pub mod prefix;
pub mod progress;
pub mod registry;
pub mod sampling;
pub mod sequence;
pub mod test_pairing;
pub mod test_stream;
pub mod tolerance;
pub mod vehicle;
pub mod warnings;

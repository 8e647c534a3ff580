//! How a library is searched (grid cases) or learned (policies), as a build
//! request names it.

use super::{PolicySolver, SearchMethod};

/// How a library is searched or learned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LibrarySearch {
    /// Over the cells of a grid case (cut-in, highway-exit).
    Cells(SearchMethod),
    /// Q-values of the car-following case.
    Policy(PolicySolver),
}

//! Where a case's exposure comes from, and why a case, a vehicle or a
//! library could not be used.

use crate::adaptive::AdaptiveError;
use crate::library::LibraryFileError;
use crate::sampling::SamplingError;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Where a case's exposure `P(x)` comes from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ExposureSource {
    /// The case's documented built-in exposure model.
    Builtin,
    /// A table in the layout of SPEC §4 (see [`crate::ndd_table`]).
    Table {
        /// The table's name, shown with campaigns and libraries.
        name: String,
        /// The table's CSV text.
        text: String,
    },
}

/// Why a case, a vehicle or a library could not be used.
#[derive(Debug, Error, PartialEq)]
pub enum CaseError {
    /// No case of that name.
    #[error("unknown case `{name}`; known cases: {known}")]
    UnknownCase {
        /// The name asked for.
        name: String,
        /// The cases there are, comma-separated.
        known: String,
    },
    /// No preset of that name for the case.
    #[error("{0}")]
    Preset(String),
    /// An exposure table that fails validation.
    #[error("exposure table `{name}` rejected: {reason}")]
    Exposure {
        /// The table's name.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A vehicle specification the case cannot run.
    #[error("invalid vehicle for case {case}: {reason}")]
    Vehicle {
        /// The case.
        case: &'static str,
        /// What is wrong with the vehicle.
        reason: String,
    },
    /// A library request the case cannot build.
    #[error("invalid library request for case {case}: {reason}")]
    Request {
        /// The case.
        case: &'static str,
        /// What is wrong with the request.
        reason: String,
    },
    /// A grid library file that cannot be used.
    #[error(transparent)]
    Library(#[from] LibraryFileError),
    /// A policy library file (car-following) that cannot be used.
    #[error("{0}")]
    PolicyFile(String),
    /// A test distribution that cannot be built.
    #[error(transparent)]
    Sampling(#[from] SamplingError),
    /// The case has no exact answer for this request (e.g. car-following).
    #[error("{0}")]
    NoExactAnswer(String),
    /// The surrogate search failed.
    #[error("the library could not be built: {0}")]
    Build(String),
    /// An adaptive campaign that cannot run.
    #[error(transparent)]
    Adaptive(#[from] AdaptiveError),
    /// What this case does not do.
    #[error("{0}")]
    Unsupported(String),
    /// A user-defined case's name already holds another definition.
    #[error("case {0} is already defined, differently: a case keeps its definition; name the new one otherwise")]
    AlreadyDefined(String),
}

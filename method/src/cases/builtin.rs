//! The built-in cases: each one's descriptor, opener and built-in table.

use super::{carfollow, cutin, highway};
use crate::descriptor::CaseDescriptor;
use crate::registry::{CaseError, ExposureSource, ScenarioCase};
use std::sync::Arc;

/// Opens a case with a preset (its default when `None`) on an exposure.
pub type Opener = fn(Option<&str>, &ExposureSource) -> Result<Arc<dyn ScenarioCase>, CaseError>;

/// A built-in case: its descriptor and how to open it.
pub struct BuiltinCase {
    /// Its descriptor.
    pub descriptor: fn() -> CaseDescriptor,
    /// Opens it with `preset` (the default when `None`) on `exposure`.
    pub open: Opener,
    /// Its built-in exposure model for `preset`, written as the table a
    /// user would upload (the format its descriptor's `tables` names).
    pub builtin_table: fn(Option<&str>) -> Result<String, CaseError>,
}

/// Every built-in case, in the order help texts list them.
pub const BUILTIN: [BuiltinCase; 3] = [
    BuiltinCase {
        descriptor: cutin::descriptor::descriptor,
        open: cutin::descriptor::open,
        builtin_table: cutin::descriptor::builtin_table,
    },
    BuiltinCase {
        descriptor: highway::descriptor::descriptor,
        open: highway::descriptor::open,
        builtin_table: highway::descriptor::builtin_table,
    },
    BuiltinCase {
        descriptor: carfollow::descriptor::descriptor,
        open: carfollow::opener::open,
        builtin_table: carfollow::descriptor::builtin_table,
    },
];

//! The cases: each lives in its own folder here and says, in one
//! [`CaseDescriptor`], everything the service and the command line need to
//! know about it: its presets, its default surrogate and library search,
//! whether its scenarios are grid cells or drawn while a test runs, the
//! exposure tables it accepts, what its progress and pictures count, the
//! pairings it is validated and reproduced on. Nothing outside a case's
//! folder matches on its name; code that differs by case asks the
//! descriptor, or the opened case ([`crate::registry::ScenarioCase`]).
//!
//! Adding a case means a folder with its descriptor and its opener, and one
//! entry in [`BUILTIN`].

pub mod carfollow;
pub mod cutin;
pub mod highway;

pub use crate::descriptor::{
    CaseDescriptor, PaperFigures, Preset, Reproduction, Scenarios, TableFormat, Validation,
};
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
}

/// Every built-in case, in the order help texts list them.
pub const BUILTIN: [BuiltinCase; 3] = [
    BuiltinCase {
        descriptor: cutin::descriptor::descriptor,
        open: cutin::descriptor::open,
    },
    BuiltinCase {
        descriptor: highway::descriptor::descriptor,
        open: highway::descriptor::open,
    },
    BuiltinCase {
        descriptor: carfollow::descriptor::descriptor,
        open: carfollow::descriptor::open,
    },
];

/// The descriptors of every case.
pub fn descriptors() -> Vec<CaseDescriptor> {
    BUILTIN.iter().map(|c| (c.descriptor)()).collect()
}

/// The names of every case, comma-separated (for messages).
pub fn known() -> String {
    BUILTIN
        .iter()
        .map(|c| (c.descriptor)().name)
        .collect::<Vec<_>>()
        .join(", ")
}

fn builtin(name: &str) -> Result<&'static BuiltinCase, CaseError> {
    BUILTIN
        .iter()
        .find(|c| (c.descriptor)().name == name)
        .ok_or_else(|| CaseError::UnknownCase {
            name: name.to_owned(),
            known: known(),
        })
}

/// The descriptor of case `name`.
pub fn descriptor(name: &str) -> Result<CaseDescriptor, CaseError> {
    builtin(name).map(|c| (c.descriptor)())
}

/// Opens case `name` with `preset` (the case's default when `None`) on
/// `exposure`.
pub fn open_case(
    name: &str,
    preset: Option<&str>,
    exposure: &ExposureSource,
) -> Result<Arc<dyn ScenarioCase>, CaseError> {
    (builtin(name)?.open)(preset, exposure)
}

/// Refuses a table for a case that has only its built-in exposure model.
pub(crate) fn builtin_exposure_only(
    case: &str,
    exposure: &ExposureSource,
) -> Result<(), CaseError> {
    if let ExposureSource::Table { name, .. } = exposure {
        return Err(CaseError::Exposure {
            name: name.clone(),
            reason: format!(
                "the {case} case has only its built-in exposure model (docs/models.md); omit \
                 the table"
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests;

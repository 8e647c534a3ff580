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
//! entry in [`BUILTIN`] (`builtin.rs`).

mod builtin;
pub use label::vehicle_label;
pub mod carfollow;
pub mod cutin;
pub mod highway;
mod label;
pub(crate) mod table_note;
pub mod user;

pub use builtin::{BuiltinCase, Opener, BUILTIN};

pub use crate::descriptor::{
    CaseDescriptor, PaperFigures, Preset, Reproduction, Scenarios, TableFormat, Validation,
};
use crate::registry::{CaseError, ExposureSource, ScenarioCase};
use std::sync::Arc;

/// The descriptors of every case: the built-in ones, then the user-defined
/// cases registered in this process ([`user::registry`]), by name.
pub fn descriptors() -> Vec<CaseDescriptor> {
    BUILTIN
        .iter()
        .map(|c| (c.descriptor)())
        .chain(user::registry::descriptors())
        .collect()
}

/// The names of every case, comma-separated (for messages).
pub fn known() -> String {
    descriptors()
        .iter()
        .map(|d| d.name)
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

/// The descriptor of case `name` (built-in or registered).
pub fn descriptor(name: &str) -> Result<CaseDescriptor, CaseError> {
    match builtin(name) {
        Ok(c) => Ok((c.descriptor)()),
        Err(e) => user::registry::descriptor(name).ok_or(e),
    }
}

/// The built-in exposure of case `name` with `preset`, as a table.
pub fn builtin_table(name: &str, preset: Option<&str>) -> Result<String, CaseError> {
    (builtin(name)?.builtin_table)(preset)
}

/// Opens case `name` (built-in, or a user-defined case registered in this
/// process) with `preset` (the case's default when `None`) on `exposure`.
pub fn open_case(
    name: &str,
    preset: Option<&str>,
    exposure: &ExposureSource,
) -> Result<Arc<dyn ScenarioCase>, CaseError> {
    match builtin(name) {
        Ok(c) => (c.open)(preset, exposure),
        Err(e) => match user::registry::get(name) {
            Some(definition) => definition.open(preset, exposure, None),
            None => Err(e),
        },
    }
}

#[cfg(test)]
mod tests;

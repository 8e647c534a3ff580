//! The user-defined cases a process knows, by name: registered from their
//! definitions (the case file and its exposure table, as text) by the
//! coordinator (its database) and the worker (a campaign's plan), so that
//! opening a case by name (`crate::cases::open_case`) finds them as it finds
//! the built-in ones. A name keeps its definition: registering another
//! under it is refused.

use super::descriptor;
use super::file::CaseFile;
use crate::cases::CaseDescriptor;
use crate::external::ProgramHost;
use crate::registry::{CaseError, ExposureSource, ScenarioCase};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::{Arc, RwLock};

/// A user-defined case as it travels and is stored: its file and its
/// exposure table, as text.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct UserCaseDefinition {
    /// The case file (TOML).
    pub file: String,
    /// The exposure table's name (the case file's `exposure`).
    pub table_name: String,
    /// The exposure table (CSV).
    pub table: String,
}

/// A checked definition.
#[derive(Debug, Clone)]
pub struct Registered {
    /// As given.
    pub definition: UserCaseDefinition,
    /// Its file, read.
    pub file: CaseFile,
}

impl Registered {
    /// Opens the case on `exposure` (its own table when built-in).
    pub fn open(
        &self,
        preset: Option<&str>,
        exposure: &ExposureSource,
        host: Option<Arc<dyn ProgramHost>>,
    ) -> Result<Arc<dyn ScenarioCase>, CaseError> {
        descriptor::open(
            self.file.clone(),
            &self.definition.table_name,
            &self.definition.table,
            preset,
            exposure,
            host,
        )
    }
}

static CASES: RwLock<BTreeMap<String, Arc<Registered>>> = RwLock::new(BTreeMap::new());

/// Checks `definition` (its file, its table on its grid) and registers it;
/// the case's name. The same definition again is accepted; another under a
/// registered name is refused.
pub fn register(definition: UserCaseDefinition) -> Result<String, CaseError> {
    let file = CaseFile::parse(&definition.file).map_err(CaseError::Unsupported)?;
    let registered = Registered {
        definition,
        file: file.clone(),
    };
    registered.open(None, &ExposureSource::Builtin, None)?;
    let mut cases = CASES.write().unwrap_or_else(|p| p.into_inner());
    if let Some(existing) = cases.get(&file.name) {
        if existing.definition != registered.definition {
            return Err(CaseError::AlreadyDefined(file.name));
        }
        return Ok(file.name);
    }
    cases.insert(file.name.clone(), Arc::new(registered));
    Ok(file.name)
}

/// The registered case `name`.
pub fn get(name: &str) -> Option<Arc<Registered>> {
    CASES
        .read()
        .unwrap_or_else(|p| p.into_inner())
        .get(name)
        .cloned()
}

/// The descriptor of the registered case `name`.
pub fn descriptor(name: &str) -> Option<CaseDescriptor> {
    get(name).map(|r| descriptor::descriptor(&r.file))
}

/// The descriptors of every registered case, by name.
pub fn descriptors() -> Vec<CaseDescriptor> {
    CASES
        .read()
        .unwrap_or_else(|p| p.into_inner())
        .values()
        .map(|r| descriptor::descriptor(&r.file))
        .collect()
}

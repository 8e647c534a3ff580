//! A campaign's vehicle under test: a built-in model of the case, or an
//! external program that the worker drives (see [`crate::external`]).

use super::CaseError;
use crate::external::{DriverError, ExternalMode, ExternalVehicle, ExternalVut, TestStart};

/// The vehicle a campaign tests.
#[derive(Debug, Clone)]
pub(crate) enum CampaignVehicle<V> {
    Builtin(V),
    External(ExternalVut),
}

impl<V> CampaignVehicle<V> {
    /// Parses `spec`: `{"external": …}` names a program (in episode mode
    /// only where the case can hand over a whole scenario), anything else
    /// goes to `builtin`.
    pub(crate) fn parse(
        case: &'static str,
        spec: &serde_json::Value,
        episode: bool,
        builtin: impl FnOnce(&serde_json::Value) -> Result<V, CaseError>,
    ) -> Result<Self, CaseError> {
        let Some(external) = ExternalVut::from_spec(spec) else {
            return builtin(spec).map(Self::Builtin);
        };
        let vut = external.map_err(|reason| CaseError::Vehicle { case, reason })?;
        if vut.mode == ExternalMode::Episode && !episode {
            return Err(CaseError::Vehicle {
                case,
                reason: "external programs drive it in step mode only: its background \
                         vehicle reacts to what the vehicle under test does, so no whole \
                         scenario exists before the test runs"
                    .into(),
            });
        }
        Ok(Self::External(vut))
    }

    /// The built-in model, or the error for `purpose` (a library build or
    /// an exact answer, which run on the coordinator).
    pub(crate) fn into_builtin(self, case: &'static str, purpose: &str) -> Result<V, CaseError> {
        match self {
            Self::Builtin(v) => Ok(v),
            Self::External(e) => Err(CaseError::Vehicle {
                case,
                reason: format!(
                    "{purpose} needs a built-in model; `{}` is an external program that only \
                     workers offering it can run",
                    e.external
                ),
            }),
        }
    }

    /// The specification written out in full, as it is stored.
    pub(crate) fn to_spec(&self) -> serde_json::Value
    where
        V: serde::Serialize,
    {
        let spec = match self {
            Self::Builtin(v) => serde_json::to_value(v),
            Self::External(e) => serde_json::to_value(e),
        };
        spec.expect("vehicle specifications serialise")
    }

    pub(crate) fn external(&self) -> Option<&ExternalVut> {
        match self {
            Self::Builtin(_) => None,
            Self::External(e) => Some(e),
        }
    }
}

/// How test `index` is run: on the built-in model, or by a program (sent
/// its `reset` first, so nothing leaks from the test before).
pub(crate) enum Runner<'v, 'p, V> {
    Builtin(&'v V),
    Program(&'p mut dyn ExternalVehicle, ExternalMode),
}

/// Picks the runner of a test: `program` when given (in the campaign's
/// mode when its vehicle is that program, else step mode), else the
/// built-in model.
pub(crate) fn runner<'v, 'p, V>(
    vehicle: &'v CampaignVehicle<V>,
    program: Option<&'p mut dyn ExternalVehicle>,
    start: TestStart<'_>,
) -> Result<Runner<'v, 'p, V>, DriverError> {
    match (program, vehicle) {
        (Some(program), vehicle) => {
            let mode = vehicle.external().map_or(ExternalMode::Step, |e| e.mode);
            program.reset(&TestStart { mode, ..start })?;
            Ok(Runner::Program(program, mode))
        }
        (None, CampaignVehicle::Builtin(v)) => Ok(Runner::Builtin(v)),
        (None, CampaignVehicle::External(e)) => Err(DriverError(format!(
            "the vehicle under test is the external program `{}`, and this runner has none",
            e.external
        ))),
    }
}

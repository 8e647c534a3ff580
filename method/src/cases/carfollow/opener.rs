//! Opening the car-following case for the service and the command line.

use super::service::FollowScenarioCase;
use super::{CarFollowing, FollowPreset};
use crate::cases::table_note::table_note;
use crate::registry::{CaseError, ExposureSource, ScenarioCase};
use std::sync::Arc;

/// Opens the car-following case with `preset` on its built-in exposure.
pub fn open(
    preset: Option<&str>,
    exposure: &ExposureSource,
) -> Result<Arc<dyn ScenarioCase>, CaseError> {
    let preset: FollowPreset = match preset {
        None => FollowPreset::default(),
        Some(p) => p.parse().map_err(CaseError::Preset)?,
    };
    let (case, note) = match exposure {
        ExposureSource::Builtin => (CarFollowing::new(preset), None),
        ExposureSource::Table { name, text } => {
            let (case, sum) =
                CarFollowing::from_tables(preset, text, name.clone()).map_err(|e| {
                    CaseError::Exposure {
                        name: name.clone(),
                        reason: e.to_string(),
                    }
                })?;
            let builtin = CarFollowing::new(preset);
            let (states, laws) = case
                .exposure
                .distance(&builtin.exposure, case.world.actions);
            let mut note = table_note(name, sum, Some(states));
            note.push_str(&format!(
                " (P(s); P(u | v): at most {laws:.3} at any speed; preset {})",
                preset.name()
            ));
            (case, Some(note))
        }
    };
    Ok(Arc::new(FollowScenarioCase::new(case).with_note(note)))
}

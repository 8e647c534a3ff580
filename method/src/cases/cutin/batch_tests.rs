//! The cut-in case's batched runs ([`super::batch`]) against its runs one
//! by one, bit for bit.

use crate::case::Case;
use crate::cases::cutin::{CutIn, CutInPreset};
use crate::vehicle::{VehicleModel, VehicleSpec};

/// Every cell of the built-in grid, batched against one by one.
fn batched_equals_scalar(case: &CutIn, vehicle: &VehicleModel) -> usize {
    let cells: Vec<usize> = (0..case.grid().len()).collect();
    let mut batched = vec![false; cells.len()];
    case.events(vehicle, &cells, &mut batched);
    for &cell in &cells {
        assert_eq!(
            batched[cell],
            case.run(vehicle, cell).accident,
            "cell {cell}, {:?}, {vehicle:?}",
            case.preset()
        );
    }
    // Out of order and a batch cut short by the end of the list.
    let odd: Vec<usize> = cells.iter().rev().step_by(3).copied().take(13).collect();
    let mut some = vec![false; odd.len()];
    case.events(vehicle, &odd, &mut some);
    for (event, &cell) in some.iter().zip(&odd) {
        assert_eq!(*event, batched[cell], "cell {cell}");
    }
    batched.iter().filter(|&&e| e).count()
}

#[test]
fn batched_outcomes_are_the_scalar_ones_on_every_cell_of_every_preset() {
    let vehicles: Vec<VehicleModel> = [
        r#"{"model": "idm"}"#,
        r#"{"model": "fvdm"}"#,
        // A real exponent (powf) and other parameters.
        r#"{"model": "idm", "delta": 3.5, "v0": 30, "headway": 1.5}"#,
        r#"{"model": "idm", "delta": 1}"#,
        r#"{"model": "fvdm", "k": 0.6, "c2": 1.2}"#,
        // Stateful followers run one by one.
        r#"{"model": "switching-acc"}"#,
        r#"{"model": "acc-aeb"}"#,
    ]
    .iter()
    .map(|text| {
        let spec: VehicleSpec = serde_json::from_str(text).unwrap();
        VehicleModel::try_from(spec).unwrap()
    })
    .collect();
    for preset in [CutInPreset::PaperCode, CutInPreset::PaperTable] {
        let case = CutIn::builtin(preset);
        for vehicle in &vehicles {
            let events = batched_equals_scalar(&case, vehicle);
            // Neither trivially safe nor trivially failing.
            assert!(events > 0 && events < case.grid().len(), "{vehicle:?}");
        }
    }
}

//! Every cell of the cut-in grid as CSV, for studying where each built-in
//! vehicle fails: the cell's range and range rate, its exposure `P(x)`,
//! each vehicle's event and mnpETTC (0 for an event: how close the test
//! came), and the criticality `V(x)` of the exhaustive IDM and FVDM
//! libraries (0 outside them). Used by `scripts/research/adaptive_prototype.py`.
//!
//! ```sh
//! cargo run --release -p tslg-method --example cutin_cells -- builtin cells.csv
//! cargo run --release -p tslg-method --example cutin_cells -- ../shared/data/cutin_ndd_spmd.csv cells.csv
//! ```

use std::io::Write;
use tslg_method::case::Case;
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::library::{build_library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::vehicle::VehicleModel;

const VEHICLES: [&str; 4] = ["idm", "fvdm", "switching-acc", "acc-aeb"];
const SURROGATES: [&str; 2] = ["idm", "fvdm"];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [exposure, out] = args.as_slice() else {
        return Err("usage: cutin_cells (builtin | TABLE.csv) OUT.csv".into());
    };
    let preset = CutInPreset::PaperCode;
    let case = if exposure == "builtin" {
        CutIn::builtin(preset)
    } else {
        let text = std::fs::read_to_string(exposure)?;
        CutIn::from_table(&text, String::from("table"), preset)?.0
    };
    let vehicles = VEHICLES
        .iter()
        .map(|name| VehicleModel::builtin(name))
        .collect::<Result<Vec<_>, _>>()?;
    let grid = case.grid();
    let mut libraries = Vec::new();
    for name in SURROGATES {
        let surrogate = VehicleModel::builtin(name)?;
        let request = LibraryRequest {
            threshold: Threshold::default(),
            search: SearchMethod::Exhaustive,
        };
        let spec = serde_json::to_value(surrogate)?;
        let library = build_library(&case, &surrogate, spec, preset.name(), &request);
        let mut v = vec![0.0; grid.len()];
        for c in &library.cells {
            v[c.cell] = c.criticality;
        }
        libraries.push(v);
    }
    let mut file = std::io::BufWriter::new(std::fs::File::create(out)?);
    write!(file, "cell,r,rr,p")?;
    for name in VEHICLES {
        write!(file, ",a_{name},c_{name}")?;
    }
    for name in SURROGATES {
        write!(file, ",v_{name}")?;
    }
    writeln!(file)?;
    for cell in 0..grid.len() {
        let p = case.exposure().p(cell);
        write!(
            file,
            "{cell},{},{},{p:e}",
            grid.value(cell, 0),
            grid.value(cell, 1)
        )?;
        for vehicle in &vehicles {
            let run = case.run(vehicle, cell);
            let event = u8::from(case.is_event(vehicle, cell));
            write!(file, ",{event},{}", run.mnp_ettc)?;
        }
        for v in &libraries {
            write!(file, ",{:e}", v[cell])?;
        }
        writeln!(file)?;
    }
    Ok(())
}

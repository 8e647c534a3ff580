//! `tslg cases`: every case with its presets, vehicles and defaults, from
//! the case descriptors (what `GET /api/v1/cases` serves).

use tslg_client::wire::{case_view, search_request};

pub fn run(json: bool) -> anyhow::Result<()> {
    let cases = tslg_method::cases::descriptors();
    if json {
        let views: Vec<_> = cases.iter().map(case_view).collect();
        println!("{}", serde_json::to_string_pretty(&views)?);
        return Ok(());
    }
    for (k, case) in cases.iter().enumerate() {
        if k > 0 {
            println!();
        }
        println!("{}", case.name);
        println!("  {}", case.summary);
        for (i, preset) in case.presets.iter().enumerate() {
            let default = if i == 0 { " (default)" } else { "" };
            println!("  preset {}{default}: {}", preset.name, preset.summary);
        }
        println!("  vehicles: {}", case.vehicles.join(", "));
        println!(
            "  library: surrogate {} by default, search {}",
            case.default_surrogate,
            serde_json::to_string(&search_request(case.default_search))?
        );
        println!(
            "  scenarios: {} ({})",
            if case.is_grid() {
                "grid cells drawn before each test; exact answers and adaptive campaigns"
            } else {
                "drawn while each test runs"
            },
            case.scenario_unit
        );
        match case.tables.as_slice() {
            [] => println!("  exposure: its built-in model only"),
            tables => {
                for t in tables {
                    println!(
                        "  exposure: built-in, or a table of {} ({})",
                        t.holds, t.doc
                    );
                }
            }
        }
    }
    Ok(())
}

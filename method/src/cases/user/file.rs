//! The case file of a user-defined grid case (TOML), read and checked:
//!
//! ```toml
//! name = "my-cut-in"
//! summary = "A vehicle cuts in at range R and range rate Ṙ."
//! event = "accident"                    # what the event is called
//! program = "cutin-idm"                 # the simulation's program (its name)
//! command = "python3 cutin_idm.py"      # how the command line starts it
//! exposure = "cut-in-exposure.csv"      # P(x): one column per dimension, then probability
//! objective_weight = 1.0                # w of J(x) = criticality + w d(x, Ω)
//!
//! [[dimensions]]
//! name = "range"
//! unit = "m"
//! lower = 1
//! upper = 89
//! step = 2
//! ```
//!
//! Paths (`exposure`, and `command` when it names a file) are relative to
//! the case file's folder; the command line resolves them, the method only
//! reads text.

use serde::Deserialize;

/// The most scenarios a user-defined grid may have.
pub const MAX_SCENARIOS: usize = 10_000_000;
/// The most dimensions.
pub const MAX_DIMENSIONS: usize = 8;

/// One dimension of a user-defined grid.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dimension {
    /// Its name: the key of the scenario the program receives.
    pub name: String,
    /// Its unit (for pictures and help).
    #[serde(default)]
    pub unit: String,
    /// The first grid value.
    pub lower: f64,
    /// The last grid value (`lower + k · step` for a whole `k`).
    pub upper: f64,
    /// The step between grid values.
    pub step: f64,
}

impl Dimension {
    /// Its number of grid values.
    pub fn count(&self) -> usize {
        ((self.upper - self.lower) / self.step).round() as usize + 1
    }
}

/// A user-defined grid case, as its file says.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaseFile {
    /// The case's name: how requests and commands name it.
    pub name: String,
    /// What it tests.
    #[serde(default)]
    pub summary: String,
    /// What the event is called (`accident`, `missed exit`).
    #[serde(default = "default_event")]
    pub event: String,
    /// The name of the program that simulates the case (episode mode):
    /// the default surrogate, and what workers must offer.
    pub program: String,
    /// How the command line starts the program (a command, split as a
    /// shell would; relative paths from the case file's folder).
    pub command: String,
    /// The exposure table: one column per dimension, then `probability`.
    pub exposure: String,
    /// `w` in the multistart objective `J(x) = criticality + w d(x, Ω)`.
    #[serde(default = "default_weight")]
    pub objective_weight: f64,
    /// The dimensions, in the order of the grid.
    pub dimensions: Vec<Dimension>,
}

fn default_event() -> String {
    "event".into()
}

fn default_weight() -> f64 {
    1.0
}

/// Whether `name` is 1 to 64 characters of `a–z 0–9 . _ -`, starting with
/// a letter or digit: what a case, a dimension or a program may be called.
fn valid_name(name: &str) -> bool {
    let first = name.chars().next();
    (1..=64).contains(&name.len())
        && first.is_some_and(|c| c.is_ascii_alphanumeric())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || "._-".contains(c))
}

impl CaseFile {
    /// Reads and checks a case file.
    pub fn parse(text: &str) -> Result<Self, String> {
        let file: CaseFile = toml::from_str(text).map_err(|e| e.to_string())?;
        file.check()?;
        Ok(file)
    }

    fn check(&self) -> Result<(), String> {
        if !valid_name(&self.name) {
            return Err(format!(
                "name `{}`: a case is named by 1 to 64 characters of a-z, 0-9, `.`, `_` and \
                 `-`, starting with a letter or digit",
                self.name
            ));
        }
        if crate::cases::builtin::BUILTIN
            .iter()
            .any(|c| (c.descriptor)().name == self.name)
        {
            return Err(format!("name `{}` is a built-in case's", self.name));
        }
        if !valid_name(&self.program) {
            return Err(format!(
                "program `{}`: a program is named by 1 to 64 characters of a-z, 0-9, `.`, `_` \
                 and `-`",
                self.program
            ));
        }
        if self.command.trim().is_empty() {
            return Err("command is empty: it says how to start the program".into());
        }
        if !(self.objective_weight.is_finite() && self.objective_weight >= 0.0) {
            return Err(format!(
                "objective_weight = {} must be a finite number ≥ 0",
                self.objective_weight
            ));
        }
        if self.dimensions.is_empty() || self.dimensions.len() > MAX_DIMENSIONS {
            return Err(format!(
                "a case has 1 to {MAX_DIMENSIONS} dimensions, not {}",
                self.dimensions.len()
            ));
        }
        let mut scenarios: usize = 1;
        for (k, d) in self.dimensions.iter().enumerate() {
            let at = format!("dimension {} (`{}`)", k + 1, d.name);
            if !valid_name(&d.name) || d.name == "probability" {
                return Err(format!(
                    "{at}: a dimension is named by 1 to 64 characters of a-z, 0-9, `.`, `_` \
                     and `-`, and not `probability`"
                ));
            }
            if self.dimensions[..k].iter().any(|e| e.name == d.name) {
                return Err(format!("{at}: two dimensions have the same name"));
            }
            if ![d.lower, d.upper, d.step].iter().all(|x| x.is_finite()) {
                return Err(format!(
                    "{at}: lower, upper and step must be finite numbers"
                ));
            }
            if d.step <= 0.0 {
                return Err(format!("{at}: step = {} must be > 0", d.step));
            }
            if d.upper < d.lower {
                return Err(format!(
                    "{at}: upper = {} is below lower = {}",
                    d.upper, d.lower
                ));
            }
            let k_steps = (d.upper - d.lower) / d.step;
            if (k_steps - k_steps.round()).abs() > 1e-6 {
                return Err(format!(
                    "{at}: upper − lower = {} is not a whole number of steps of {}",
                    d.upper - d.lower,
                    d.step
                ));
            }
            scenarios = scenarios.saturating_mul(d.count());
        }
        if scenarios > MAX_SCENARIOS {
            return Err(format!(
                "the grid has {scenarios} scenarios; a case has at most {MAX_SCENARIOS}"
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
name = "my-cut-in"
program = "cutin-idm"
command = "python3 cutin_idm.py"
exposure = "exposure.csv"

[[dimensions]]
name = "range"
unit = "m"
lower = 1
upper = 89
step = 2

[[dimensions]]
name = "range_rate"
unit = "m/s"
lower = -20
upper = 10
step = 0.4
"#;

    #[test]
    fn a_case_file_reads_with_its_defaults() {
        let f = CaseFile::parse(GOOD).unwrap();
        assert_eq!(f.dimensions.len(), 2);
        assert_eq!(f.dimensions[0].count(), 45);
        assert_eq!(f.dimensions[1].count(), 76);
        assert_eq!((f.event.as_str(), f.objective_weight), ("event", 1.0));
    }

    #[test]
    fn bad_case_files_say_why() {
        let err = |text: &str| CaseFile::parse(text).unwrap_err();
        let with = |from: &str, to: &str| GOOD.replacen(from, to, 1);
        assert!(err(&with("step = 2", "step = 0"))
            .contains("dimension 1 (`range`): step = 0 must be > 0"));
        assert!(err(&with("upper = 89", "upper = 88")).contains("not a whole number of steps"));
        assert!(err(&with("upper = 89", "upper = -3")).contains("is below lower"));
        assert!(err(&with("name = \"range_rate\"", "name = \"range\"")).contains("same name"));
        assert!(err(&with("name = \"my-cut-in\"", "name = \"cut-in\"")).contains("built-in"));
        assert!(err(&with("name = \"my-cut-in\"", "name = \"My Case\"")).contains("a-z"));
        assert!(
            err(&with("exposure = \"exposure.csv\"\n", "")).contains("missing field `exposure`")
        );
        assert!(
            err(&with("unit = \"m\"", "unit = \"m\"\nsteps = 3")).contains("unknown field `steps`")
        );
        let header = GOOD.split("[[dimensions]]").next().unwrap();
        assert!(err(header).contains("missing field `dimensions`"));
        assert!(err(&format!("{header}dimensions = []\n")).contains("1 to 8 dimensions, not 0"));
        assert!(err(&with("step = 0.4", "step = 0.000001")).contains("at most 10000000"));
    }
}

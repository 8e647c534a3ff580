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
/// The longest `summary`, in bytes: every `GET /api/v1/cases` returns it.
pub const MAX_SUMMARY: usize = 2_000;
/// The longest `command`, `exposure` and other free text of a case file,
/// in bytes (names are 1 to 64 characters; see `valid_name`).
pub const MAX_TEXT: usize = 1_000;
/// The longest `event` and dimension `unit`, in bytes.
pub const MAX_LABEL: usize = 64;

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
    /// Its number of grid values, `(upper − lower)/step + 1`, or `None`
    /// when that is more than a case may have ([`MAX_SCENARIOS`]): a cast
    /// of 10²⁰ steps to `usize` saturates and `+ 1` then wraps to 0.
    pub fn checked_count(&self) -> Option<usize> {
        let steps = ((self.upper - self.lower) / self.step).round();
        (steps.is_finite() && (0.0..MAX_SCENARIOS as f64).contains(&steps))
            .then(|| steps as usize + 1)
    }

    /// Its number of grid values, for a dimension that passed
    /// [`CaseFile::parse`] (at most [`MAX_SCENARIOS`]).
    pub fn count(&self) -> usize {
        self.checked_count().unwrap_or(MAX_SCENARIOS + 1)
    }
}

/// `text` when it is at most `max` bytes without control characters
/// (a newline and a tab excepted where `lines` allows them).
fn check_text(field: &str, text: &str, max: usize, lines: bool) -> Result<(), String> {
    if text.len() > max {
        return Err(format!(
            "{field} is {} bytes; at most {max} are kept",
            text.len()
        ));
    }
    if text
        .chars()
        .any(|c| c.is_control() && !(lines && (c == '\n' || c == '\t')))
    {
        return Err(format!("{field} holds a control character"));
    }
    Ok(())
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
        check_text("summary", &self.summary, MAX_SUMMARY, true)?;
        check_text("event", &self.event, MAX_LABEL, false)?;
        check_text("command", &self.command, MAX_TEXT, false)?;
        check_text("exposure", &self.exposure, MAX_TEXT, false)?;
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
            check_text(&format!("{at}: unit"), &d.unit, MAX_LABEL, false)?;
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
            let too_many = || {
                format!(
                    "the grid has more than {MAX_SCENARIOS} scenarios (the most a case has) \
                     by {at}"
                )
            };
            let count = d.checked_count().ok_or_else(too_many)?;
            scenarios = scenarios
                .checked_mul(count)
                .filter(|&n| n <= MAX_SCENARIOS)
                .ok_or_else(too_many)?;
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
        assert!(err(&with("step = 0.4", "step = 0.000001"))
            .contains("more than 10000000 scenarios (the most a case has) by dimension 2"));
    }

    /// 10¹² × 10²⁰ cells: the second count cast to `usize` saturated and
    /// `+ 1` wrapped to 0 in release, so the product passed the check and
    /// the coordinator tried to allocate terabytes (SIGABRT); 2⁶² cells
    /// overflowed the `+ 1` in debug (a 500).
    #[test]
    fn grids_too_large_for_a_usize_are_refused_before_any_product() {
        let err = |text: &str| CaseFile::parse(text).unwrap_err();
        let huge = GOOD
            .replacen("upper = 89\nstep = 2", "upper = 1e12\nstep = 1", 1)
            .replacen("upper = 10\nstep = 0.4", "upper = 1e20\nstep = 1", 1);
        assert!(
            err(&huge).contains("by dimension 1 (`range`)"),
            "{}",
            err(&huge)
        );
        let wide = GOOD.replacen(
            "lower = -20\nupper = 10\nstep = 0.4",
            "lower = 0\nupper = 4611686018427387904\nstep = 1",
            1,
        );
        assert!(
            err(&wide).contains("by dimension 2 (`range_rate`)"),
            "{}",
            err(&wide)
        );
        // Each alone fits, the product does not: 4,000 × 4,000 = 1.6 × 10⁷.
        let product = GOOD
            .replacen("upper = 89\nstep = 2", "upper = 4000\nstep = 1", 1)
            .replacen("upper = 10\nstep = 0.4", "upper = 3979\nstep = 1", 1);
        assert!(
            err(&product).contains("by dimension 2"),
            "{}",
            err(&product)
        );
        for d in CaseFile::parse(GOOD).unwrap().dimensions {
            assert_eq!(d.checked_count(), Some(d.count()));
        }
    }

    /// A 12 MB summary was stored and returned by every `GET /api/v1/cases`.
    #[test]
    fn free_text_has_a_length_limit_and_no_control_characters() {
        let err = |text: &str| CaseFile::parse(text).unwrap_err();
        let with_summary = |summary: &str| {
            GOOD.replacen(
                "program = ",
                &format!(
                    "summary = \"{}\"\nprogram = ",
                    summary.replace('\n', "\\n").replace('\u{1b}', "\\u001b")
                ),
                1,
            )
        };
        let long = "a".repeat(12_000_000);
        assert!(err(&with_summary(&long)).contains("summary is 12000000 bytes; at most 2000"));
        let fits = "b".repeat(MAX_SUMMARY);
        assert_eq!(CaseFile::parse(&with_summary(&fits)).unwrap().summary, fits);
        // Two lines are a summary; an escape sequence is not.
        assert!(CaseFile::parse(&with_summary("one\ntwo")).is_ok());
        assert!(err(&with_summary("red \u{1b}[31m")).contains("summary holds a control"));
        let long_command = format!("command = \"{}\"", "x".repeat(MAX_TEXT + 1));
        assert!(
            err(&GOOD.replacen("command = \"python3 cutin_idm.py\"", &long_command, 1))
                .contains("command is 1001 bytes")
        );
        let long_unit = format!("unit = \"{}\"", "m".repeat(MAX_LABEL + 1));
        assert!(err(&GOOD.replacen("unit = \"m\"", &long_unit, 1))
            .contains("dimension 1 (`range`): unit is 65 bytes"));
        assert!(
            err(&GOOD.replacen("program = ", "event = \"a\\nb\"\nprogram = ", 1))
                .contains("event holds a control")
        );
    }
}

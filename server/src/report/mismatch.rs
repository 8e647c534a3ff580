//! A reported outcome that another run of the same test contradicts, and
//! outcomes as the audits store them, in words.

/// A reported outcome the coordinator's own run contradicts.
#[derive(Debug, Clone, PartialEq)]
pub struct Mismatch {
    pub index: u64,
    pub reported: String,
    pub replayed: String,
}

/// An outcome as stored (`store::audits::encode`: `none`, `invalid`,
/// `event:` and the weight's bits in hex), in words.
pub fn describe(outcome: &str) -> String {
    match outcome.strip_prefix("event:") {
        Some(bits) => {
            let w = u64::from_str_radix(bits, 16)
                .map(f64::from_bits)
                .unwrap_or(f64::NAN);
            format!("an event of weight {w:e}")
        }
        None if outcome == "none" => "no event".into(),
        None => outcome.into(),
    }
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "test {} was reported as {}, but the coordinator's run gives {}",
            self.index,
            describe(&self.reported),
            describe(&self.replayed)
        )
    }
}

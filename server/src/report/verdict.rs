//! What an audit run decided: shared by the exact audits
//! ([`crate::report::audit`]) and the statistical ones of noisy programs
//! ([`crate::report::noisy`]).

/// What an audit run decided.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Two runs agree, or a run is still needed.
    Pending,
    Agreed,
    /// `liar` is in the minority of three, or its noisy program behaves
    /// unlike the others'.
    Liar {
        liar: String,
        detail: String,
    },
    /// Three runs, three outcomes, or two runs of a noisy program that
    /// differ: nobody is flagged, and the first run stands.
    Undecided,
}

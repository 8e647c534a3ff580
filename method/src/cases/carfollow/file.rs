//! The car-following library file: a compact binary form of the Q-table.
//!
//! The dense table has 45,885 × 31 = 1.4 million values, but `Q(s, ·)` is
//! zero outside the dangerous states (≈ 8 % of them), so the file holds only
//! the rows with some `Q > 0` (≈ 0.9 MB instead of 11 MB of f64 or ~30 MB
//! of JSON). Layout, all integers and floats little-endian:
//!
//! ```text
//! magic      8 bytes  "TSLGPOL\0"
//! header_len u32      length of the header
//! header     JSON     PolicyHeader (format version, case, preset, surrogate,
//!                     exposure, solver, grid size, μ_S, …)
//! rows       u32      number of stored rows
//! per row    u32 state index (strictly increasing), then `actions` × f64 Q
//! ```
//!
//! Reading checks every length, index and value, so a truncated or altered
//! file is rejected with the reason rather than sampled from.

use super::case::PolicySolver;
use super::library::PolicyLibrary;
use crate::library::ExposureRef;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The first eight bytes of every policy library file.
pub const MAGIC: &[u8; 8] = crate::library::POLICY_MAGIC;
/// The current format version.
pub const VERSION: u32 = 1;
/// The media type the service serves the file with.
pub const MEDIA_TYPE: &str = "application/vnd.tslg.policy-library";

/// Everything about a policy library except its Q-values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyHeader {
    /// The format version ([`VERSION`]).
    pub version: u32,
    /// The case (`car-following`).
    pub case: String,
    /// The case's preset.
    pub preset: String,
    /// The surrogate model, as its full specification.
    pub surrogate: serde_json::Value,
    /// The exposure the library was learned on.
    pub exposure: ExposureRef,
    /// The solver that learned the Q-values.
    pub solver: PolicySolver,
    /// DP sweeps or TD updates until the tolerance held.
    pub iterations: u64,
    /// Grid states and actions per state.
    pub states: usize,
    /// Actions per state (31 on the paper's grid).
    pub actions: usize,
    /// `μ_S = Σ_s P(s) P(S|s)`.
    pub mu_s: f64,
    /// States with `P(S|s) > 0` and their exposure `Σ P(s)`.
    pub library_states: usize,
    /// `P(Φ) = Σ_{s∈Φ} P(s)`.
    pub library_exposure: f64,
    /// One-decision surrogate simulations the build used.
    pub sm_evaluations: usize,
}

/// A policy library with its header, as stored and served.
#[derive(Debug, Clone, PartialEq)]
pub struct PolicyLibraryFile {
    /// Everything but the Q-values.
    pub header: PolicyHeader,
    /// The Q-values and `P(S|s)`.
    pub library: PolicyLibrary,
}

/// Why a policy library file was refused.
#[derive(Debug, Error, PartialEq)]
pub enum PolicyFileError {
    /// Not a policy library file: wrong magic, header or length.
    #[error("not a car-following library file: {0}")]
    Malformed(String),
    /// A format version this build cannot read.
    #[error("car-following library format version {0} is not supported (this build reads version {VERSION})")]
    Version(u32),
    /// A row of Q-values that is not a valid sub-probability.
    #[error("row {row} (state {state}): {reason}")]
    BadRow {
        /// The row's position in the file.
        row: usize,
        /// Its grid state.
        state: usize,
        /// What is wrong with it.
        reason: String,
    },
}

/// A cursor over the file's bytes that reports what was cut short.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], PolicyFileError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| {
            PolicyFileError::Malformed(format!(
                "the file ends inside the {what} (byte {} of {})",
                self.at,
                self.bytes.len()
            ))
        })?;
        let slice = &self.bytes[self.at..end];
        self.at = end;
        Ok(slice)
    }

    fn u32(&mut self, what: &str) -> Result<u32, PolicyFileError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes(b.try_into().expect("4 bytes")))
    }

    fn f64(&mut self, what: &str) -> Result<f64, PolicyFileError> {
        let b = self.take(8, what)?;
        Ok(f64::from_le_bytes(b.try_into().expect("8 bytes")))
    }
}

/// Rows whose sum exceeds 1 by more than this are rejected: `Σ_u Q(s, u)`
/// is a probability.
const ROW_SUM_SLACK: f64 = 1e-9;

impl PolicyLibraryFile {
    /// The file's bytes: magic, header length, JSON header, then the Q-values as little-endian `f64`.
    pub fn to_bytes(&self) -> Vec<u8> {
        let header = serde_json::to_vec(&self.header).expect("headers serialise");
        let actions = self.library.actions;
        let rows: Vec<usize> = (0..self.library.challenge.len())
            .filter(|&s| self.row(s).iter().any(|&q| q > 0.0))
            .collect();
        let mut out = Vec::with_capacity(16 + header.len() + rows.len() * (4 + 8 * actions));
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(header.len() as u32).to_le_bytes());
        out.extend_from_slice(&header);
        out.extend_from_slice(&(rows.len() as u32).to_le_bytes());
        for s in rows {
            out.extend_from_slice(&(s as u32).to_le_bytes());
            for q in self.row(s) {
                out.extend_from_slice(&q.to_le_bytes());
            }
        }
        out
    }

    fn row(&self, s: usize) -> &[f64] {
        let a = self.library.actions;
        &self.library.q[s * a..(s + 1) * a]
    }

    /// Reads a file of any table size (up to 2²⁸ values).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, PolicyFileError> {
        Self::read(bytes, None)
    }

    /// Reads a file whose table must have `states × actions` entries; the
    /// header is checked before anything is allocated.
    pub fn from_bytes_for(
        bytes: &[u8],
        states: usize,
        actions: usize,
    ) -> Result<Self, PolicyFileError> {
        Self::read(bytes, Some((states, actions)))
    }

    fn read(bytes: &[u8], expected: Option<(usize, usize)>) -> Result<Self, PolicyFileError> {
        let mut r = Reader { bytes, at: 0 };
        if r.take(MAGIC.len(), "magic number")? != MAGIC {
            return Err(PolicyFileError::Malformed(
                "it does not start with TSLGPOL".into(),
            ));
        }
        let header_len = r.u32("header length")? as usize;
        let text = r.take(header_len, "header")?;
        // The version first: another version's header may have other fields.
        #[derive(Deserialize)]
        struct Versioned {
            version: u32,
        }
        let malformed = |e: serde_json::Error| PolicyFileError::Malformed(format!("header: {e}"));
        let versioned: Versioned = serde_json::from_slice(text).map_err(malformed)?;
        if versioned.version != VERSION {
            return Err(PolicyFileError::Version(versioned.version));
        }
        let header: PolicyHeader = serde_json::from_slice(text).map_err(malformed)?;
        let (states, actions) = (header.states, header.actions);
        if let Some((s, a)) = expected.filter(|&e| e != (states, actions)) {
            return Err(PolicyFileError::Malformed(format!(
                "its table has {states} states × {actions} actions; this case has {s} × {a}"
            )));
        }
        if states == 0 || actions == 0 || states.checked_mul(actions).is_none_or(|n| n > 1 << 28) {
            return Err(PolicyFileError::Malformed(format!(
                "header: {states} states × {actions} actions is not a table this build reads"
            )));
        }
        let rows = r.u32("row count")? as usize;
        let mut q = vec![0.0; states * actions];
        let mut previous: Option<usize> = None;
        for row in 0..rows {
            let state = r.u32("row index")? as usize;
            let bad = |reason: String| PolicyFileError::BadRow { row, state, reason };
            if state >= states {
                return Err(bad(format!("the grid has {states} states")));
            }
            if previous.is_some_and(|p| state <= p) {
                return Err(bad("state indices must increase strictly".into()));
            }
            previous = Some(state);
            let mut sum = 0.0;
            for k in 0..actions {
                let value = r.f64("Q-values")?;
                if !(value.is_finite() && value >= 0.0) {
                    return Err(bad(format!("Q of action {k} is {value}; Q-values are ≥ 0")));
                }
                sum += value;
                q[state * actions + k] = value;
            }
            if sum > 1.0 + ROW_SUM_SLACK {
                return Err(bad(format!("Σ_u Q = {sum} exceeds 1")));
            }
        }
        if r.at != bytes.len() {
            return Err(PolicyFileError::Malformed(format!(
                "{} bytes follow the last row",
                bytes.len() - r.at
            )));
        }
        let library = PolicyLibrary::new(actions, q, header.iterations);
        Ok(Self { header, library })
    }
}

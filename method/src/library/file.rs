//! The library file: JSON with a format name and version, validated on read.
//! A library file is small (one entry per library cell), so JSON costs little
//! and stays readable; `docs/library-format.md` documents every field.

use super::definition::Library;
use crate::case::Case;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The format tag written into every library file.
pub const FORMAT: &str = "tslg-library";
/// The current format version.
pub const VERSION: u32 = 1;

/// Why a library file was refused.
#[derive(Debug, Error, PartialEq)]
pub enum LibraryFileError {
    /// The text is not JSON of a library's shape (serde's message).
    #[error("not a library file: {0}")]
    Json(String),
    /// The `format` tag is not this project's.
    #[error("not a library file: format is `{0}`, expected `{FORMAT}`")]
    Format(String),
    /// A format version this build cannot read.
    #[error("library format version {0} is not supported (this build reads version {VERSION})")]
    Version(u32),
    /// A cell number beyond the grid.
    #[error("library cell {index}: cell number {cell} is outside the grid of {cells} cells")]
    CellOutOfRange {
        /// Position of the offending entry in `cells`.
        index: usize,
        /// The cell number it gives.
        cell: usize,
        /// Cells of the grid.
        cells: usize,
    },
    #[error(
        "library cell {index}: cell numbers must increase strictly ({cell} follows {previous})"
    )]
    /// Cells out of order or repeated.
    CellsNotIncreasing {
        /// Position of the offending entry in `cells`.
        index: usize,
        /// The cell number it gives.
        cell: usize,
        /// The cell number before it.
        previous: usize,
    },
    /// A criticality that is not finite or not above γ.
    #[error("library cell {index}: criticality {value} must be a finite number above γ = {gamma}")]
    BadCriticality {
        /// Position of the offending entry in `cells`.
        index: usize,
        /// Its criticality.
        value: f64,
        /// The library's γ.
        gamma: f64,
    },
    /// A summary field out of its range (γ, μ_S, W).
    #[error("library field `{field}` = {value} is invalid: {reason}")]
    BadField {
        /// The field's name.
        field: &'static str,
        /// Its value.
        value: f64,
        /// The range it must be in.
        reason: &'static str,
    },
    /// The library is for another case.
    #[error("the library is for case `{library}`, not `{expected}`")]
    WrongCase {
        /// The library's case.
        library: String,
        /// The case it was opened for.
        expected: String,
    },
    /// The library was built on another exposure than the campaign's.
    #[error("the library was built on exposure {library} but this campaign uses {campaign}; build the library on the same exposure")]
    WrongExposure {
        /// The library's exposure (name and fingerprint).
        library: String,
        /// The campaign's exposure.
        campaign: String,
    },
}

/// The file as written: the format tag and version, then the library's
/// fields. (Read back through [`Library::from_json`], which takes the tag
/// and version off and refuses unknown fields; serde's `flatten` cannot.)
#[derive(Serialize)]
struct LibraryFile<'a> {
    format: &'static str,
    version: u32,
    #[serde(flatten)]
    library: &'a Library,
}

#[derive(Deserialize)]
struct Header {
    format: Option<String>,
    version: Option<u32>,
}

impl Library {
    /// The library as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(&LibraryFile {
            format: FORMAT,
            version: VERSION,
            library: self,
        })
        .expect("a library serialises")
    }

    /// Reads and validates a library file.
    pub fn from_json(text: &str) -> Result<Self, LibraryFileError> {
        let header: Header =
            serde_json::from_str(text).map_err(|e| LibraryFileError::Json(e.to_string()))?;
        match header.format.as_deref() {
            Some(FORMAT) => {}
            Some(other) => return Err(LibraryFileError::Format(other.to_owned())),
            None => return Err(LibraryFileError::Format(String::new())),
        }
        if header.version != Some(VERSION) {
            return Err(LibraryFileError::Version(header.version.unwrap_or(0)));
        }
        // Every other field must be the library's: a misspelt or foreign
        // field is refused, not silently dropped.
        let mut fields: serde_json::Map<String, serde_json::Value> =
            serde_json::from_str(text).map_err(|e| LibraryFileError::Json(e.to_string()))?;
        fields.remove("format");
        fields.remove("version");
        let library: Library = serde_json::from_value(serde_json::Value::Object(fields))
            .map_err(|e| LibraryFileError::Json(e.to_string()))?;
        library.validate()?;
        Ok(library)
    }

    fn validate(&self) -> Result<(), LibraryFileError> {
        let positive = |field, value: f64| {
            if value.is_finite() && value >= 0.0 {
                Ok(())
            } else {
                Err(LibraryFileError::BadField {
                    field,
                    value,
                    reason: "must be a finite number ≥ 0",
                })
            }
        };
        positive("gamma", self.gamma)?;
        positive("mu_s", self.mu_s)?;
        positive("w", self.w)?;
        let cells = self.grid.len();
        let mut sum = 0.0;
        for (index, c) in self.cells.iter().enumerate() {
            if c.cell >= cells {
                return Err(LibraryFileError::CellOutOfRange {
                    index,
                    cell: c.cell,
                    cells,
                });
            }
            if index > 0 && c.cell <= self.cells[index - 1].cell {
                return Err(LibraryFileError::CellsNotIncreasing {
                    index,
                    cell: c.cell,
                    previous: self.cells[index - 1].cell,
                });
            }
            if !(c.criticality.is_finite() && c.criticality > self.gamma && c.criticality <= 1.0) {
                return Err(LibraryFileError::BadCriticality {
                    index,
                    value: c.criticality,
                    gamma: self.gamma,
                });
            }
            sum += c.criticality;
        }
        if (sum - self.w).abs() > 1e-9 * sum.max(1e-300) + 1e-15 {
            return Err(LibraryFileError::BadField {
                field: "w",
                value: self.w,
                reason: "differs from the sum of the cells' criticality",
            });
        }
        Ok(())
    }
}

impl Library {
    /// Checks that this library belongs to `case` (name, grid and exposure).
    pub fn check_matches<C: Case>(&self, case: &C) -> Result<(), LibraryFileError> {
        if self.case != case.name() {
            return Err(LibraryFileError::WrongCase {
                library: self.case.clone(),
                expected: case.name().to_owned(),
            });
        }
        let fingerprint = case.exposure().fingerprint();
        if self.exposure.fingerprint != fingerprint {
            return Err(LibraryFileError::WrongExposure {
                library: format!("{} ({})", self.exposure.name, self.exposure.fingerprint),
                campaign: format!("{} ({})", case.exposure_name(), fingerprint),
            });
        }
        Ok(())
    }
}

//! The library file: JSON with a format name and version, validated on read.
//! A library file is small (one entry per library cell), so JSON costs little
//! and stays readable; `docs/library-format.md` documents every field.

use super::Library;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The format tag written into every library file.
pub const FORMAT: &str = "tslg-library";
/// The current format version.
pub const VERSION: u32 = 1;

#[derive(Debug, Error, PartialEq)]
pub enum LibraryFileError {
    #[error("not a library file: {0}")]
    Json(String),
    #[error("not a library file: format is `{0}`, expected `{FORMAT}`")]
    Format(String),
    #[error("library format version {0} is not supported (this build reads version {VERSION})")]
    Version(u32),
    #[error("library cell {index}: cell number {cell} is outside the grid of {cells} cells")]
    CellOutOfRange {
        index: usize,
        cell: usize,
        cells: usize,
    },
    #[error(
        "library cell {index}: cell numbers must increase strictly ({cell} follows {previous})"
    )]
    CellsNotIncreasing {
        index: usize,
        cell: usize,
        previous: usize,
    },
    #[error("library cell {index}: criticality {value} must be a finite number above γ = {gamma}")]
    BadCriticality {
        index: usize,
        value: f64,
        gamma: f64,
    },
    #[error("library field `{field}` = {value} is invalid: {reason}")]
    BadField {
        field: &'static str,
        value: f64,
        reason: &'static str,
    },
    #[error("the library is for case `{library}`, not `{expected}`")]
    WrongCase { library: String, expected: String },
    #[error("the library was built on exposure {library} but this campaign uses {campaign}; build the library on the same exposure")]
    WrongExposure { library: String, campaign: String },
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

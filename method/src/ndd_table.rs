//! Reader for two-dimensional exposure tables in the layout of the authors'
//! cut-in table: row 0 is an empty corner cell followed by the column-axis
//! labels; every later row is a row-axis label followed by one probability per
//! column. The body is a joint probability mass over (row label, column label).
//!
//! Errors name the problem and the place as a 1-based line and field number,
//! the way a spreadsheet or editor shows them.

use crate::grid::{Axis, Grid, GridError};
use crate::mass::{GridMass, MassError};
use thiserror::Error;

/// Why a table was rejected.
#[derive(Debug, Error, PartialEq)]
pub enum TableError {
    /// No text at all.
    #[error("the table is empty")]
    Empty,
    /// A header but no data rows.
    #[error("the table has a header line but no data rows")]
    NoRows,
    /// The header lacks the corner cell or the column labels.
    #[error("line 1 (the header) must hold an empty corner cell and at least one column label, but it has {fields} field(s)")]
    HeaderTooShort {
        /// Fields of the header line.
        fields: usize,
    },
    /// A row with another number of fields than the header.
    #[error("line {line} has {actual} fields but the header has {expected}: every row needs a label and one value per column")]
    WrongShape {
        /// Line number (from 1).
        line: usize,
        /// Fields of the header.
        expected: usize,
        /// Fields of this line.
        actual: usize,
    },
    /// A field that is not a number.
    #[error("line {line}, field {field}: `{text}` is not a number{hint}", hint = if *line == 1 {
        " (this case's table is a matrix: its first line holds an empty corner cell, then \
         the column labels as numbers; a first line of column names is another case's \
         table; `tslg table` prints this case's)"
    } else {
        ""
    })]
    NotNumeric {
        /// Line number (from 1).
        line: usize,
        /// Field number (from 1).
        field: usize,
        /// The field's text.
        text: String,
    },
    /// A probability that is NaN or infinite.
    #[error("line {line}, field {field}: the value is {value}; probabilities must be finite")]
    NotFinite {
        /// Line number (from 1).
        line: usize,
        /// Field number (from 1).
        field: usize,
        /// The value.
        value: f64,
    },
    /// A negative probability.
    #[error("line {line}, field {field}: the probability {value} is negative")]
    Negative {
        /// Line number (from 1).
        line: usize,
        /// Field number (from 1).
        field: usize,
        /// The value.
        value: f64,
    },
    /// Row or column labels that do not form an evenly spaced grid.
    #[error("labels: {0}")]
    Labels(GridError),
    /// The mass does not sum to 1 within the tolerance.
    #[error("the probabilities sum to {sum}, which differs from 1 by more than {tolerance}")]
    SumOff {
        /// The table's total mass.
        sum: f64,
        /// The accepted distance from 1.
        tolerance: f64,
    },
    /// A long table's header holds a number where a column name belongs.
    #[error(
        "line {line}, field {field}: a block starts with a header naming its columns, not a number"
    )]
    HeaderNotNamed {
        /// Line number (from 1).
        line: usize,
        /// Field number (from 1).
        field: usize,
    },
    /// More rows than a block may hold.
    #[error("a block holds more than {max} rows")]
    TooManyRows {
        /// The limit.
        max: usize,
    },
    /// A key value that is not a value of its grid axis.
    #[error("line {line}, field {field}: {column} = {value} is not on the grid ({axis})")]
    OffGrid {
        /// Line number (from 1).
        line: usize,
        /// Field number (from 1).
        field: usize,
        /// The column.
        column: String,
        /// The value.
        value: f64,
        /// The axis' values, in words.
        axis: String,
    },
    /// Two rows for the same point.
    #[error("line {line} gives the same point as line {first}")]
    Duplicate {
        /// The later line.
        line: usize,
        /// The first line.
        first: usize,
    },
    /// A block the case needs is not in the file.
    #[error("{what} is missing: a block with columns {columns}")]
    MissingBlock {
        /// What the block holds.
        what: String,
        /// Its columns.
        columns: String,
    },
    /// The same block twice.
    #[error("line {line} repeats the block of line {first}")]
    DuplicateBlock {
        /// The second block's header line.
        line: usize,
        /// The first one's.
        first: usize,
    },
    /// A block with columns the case does not read.
    #[error("line {line}: a block with columns {columns} is not one this case reads ({expected})")]
    UnknownBlock {
        /// The header's line.
        line: usize,
        /// Its columns.
        columns: String,
        /// The blocks the case reads.
        expected: String,
    },
    /// A table that is valid but says something the case cannot use.
    #[error("{0}")]
    Unusable(String),
}

/// A validated exposure table.
#[derive(Debug, Clone, PartialEq)]
pub struct NddTable {
    /// The probability mass `P(x)` on the grid the labels describe.
    pub mass: GridMass,
}

impl NddTable {
    /// The deviation from 1 of the sum as read (zero when none), which the
    /// reader removed by renormalising; callers report it.
    pub fn renormalised_by(&self) -> f64 {
        self.mass.original_sum() - 1.0
    }
}

/// Parses `text` as a table whose row labels form axis `row_axis` and whose
/// column labels form axis `column_axis`.
pub fn parse_table(text: &str, row_axis: &str, column_axis: &str) -> Result<NddTable, TableError> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
        .filter(|(_, l)| !l.trim().is_empty());
    let (header_line, header) = lines.next().ok_or(TableError::Empty)?;
    let header_fields: Vec<&str> = header.split(',').collect();
    if header_fields.len() < 2 {
        return Err(TableError::HeaderTooShort {
            fields: header_fields.len(),
        });
    }
    let columns = header_fields.len() - 1;
    let column_labels = header_fields[1..]
        .iter()
        .enumerate()
        .map(|(k, text)| number(text, header_line, k + 2))
        .collect::<Result<Vec<_>, _>>()?;

    let mut row_labels = Vec::new();
    let mut body = Vec::new();
    for (line, content) in lines {
        let fields: Vec<&str> = content.split(',').collect();
        if fields.len() != columns + 1 {
            return Err(TableError::WrongShape {
                line,
                expected: columns + 1,
                actual: fields.len(),
            });
        }
        row_labels.push(number(fields[0], line, 1)?);
        for (k, text) in fields[1..].iter().enumerate() {
            let field = k + 2;
            let value = number(text, line, field)?;
            if !value.is_finite() {
                return Err(TableError::NotFinite { line, field, value });
            }
            if value < 0.0 {
                return Err(TableError::Negative { line, field, value });
            }
            body.push(value);
        }
    }
    if row_labels.is_empty() {
        return Err(TableError::NoRows);
    }
    let grid = Grid::new(vec![
        Axis::new(row_axis, row_labels).map_err(TableError::Labels)?,
        Axis::new(column_axis, column_labels).map_err(TableError::Labels)?,
    ])
    .map_err(TableError::Labels)?;
    let mass = GridMass::new(grid, body).map_err(|e| match e {
        MassError::SumOff { sum, tolerance } => TableError::SumOff { sum, tolerance },
        // Cells were checked above with their line and field.
        other => unreachable!("cell check missed {other}"),
    })?;
    Ok(NddTable { mass })
}

fn number(text: &str, line: usize, field: usize) -> Result<f64, TableError> {
    let trimmed = text.trim().trim_matches('"').trim();
    trimmed.parse::<f64>().map_err(|_| TableError::NotNumeric {
        line,
        field,
        text: text.trim().to_owned(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<NddTable, TableError> {
        parse_table(text, "range", "range_rate")
    }

    #[test]
    fn reads_a_small_table() {
        let t = parse(",-1,0,1\n2,0.1,0.2,0.1\n4,0.2,0.3,0.1\n").unwrap();
        let g = t.mass.grid();
        assert_eq!(g.len(), 6);
        assert_eq!(g.values(4), vec![4.0, 0.0]);
        assert!((t.mass.p(4) - 0.3).abs() < 1e-15);
        assert!(t.renormalised_by().abs() < 1e-12);
    }

    #[test]
    fn small_deviation_is_renormalised_and_reported() {
        let t = parse(",0,1\n1,0.5,0.50002\n").unwrap();
        assert!((t.renormalised_by() - 2e-5).abs() < 1e-12);
        assert!((t.mass.p(0) + t.mass.p(1) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn each_problem_names_its_place() {
        assert_eq!(parse(""), Err(TableError::Empty));
        assert_eq!(parse(",0,1\n"), Err(TableError::NoRows));
        assert_eq!(
            parse(",0,1\n1,0.5\n"),
            Err(TableError::WrongShape {
                line: 2,
                expected: 3,
                actual: 2
            })
        );
        assert_eq!(
            parse(",0,1\n1,0.5,abc\n"),
            Err(TableError::NotNumeric {
                line: 2,
                field: 3,
                text: "abc".into()
            })
        );
        assert!(matches!(
            parse(",0,1\n1,NaN,1\n"),
            Err(TableError::NotFinite {
                line: 2,
                field: 2,
                ..
            })
        ));
        assert_eq!(
            parse(",0,1\n1,1.5,-0.5\n"),
            Err(TableError::Negative {
                line: 2,
                field: 3,
                value: -0.5
            })
        );
        assert_eq!(
            parse(",0,1\n1,0.5,0.6\n"),
            Err(TableError::SumOff {
                sum: 1.1,
                tolerance: 1e-4
            })
        );
        assert!(matches!(
            parse(",1,0\n1,0.5,0.5\n"),
            Err(TableError::Labels(GridError::NotIncreasing { .. }))
        ));
    }

    #[test]
    fn error_messages_say_where() {
        let e = parse(",0,1\n1,0.5,x\n").unwrap_err().to_string();
        assert_eq!(e, "line 2, field 3: `x` is not a number");
    }
}

//! Reader for exposure tables in long form: CSV blocks whose header names
//! the columns, one row per point of a grid, the probability last. A file
//! may hold several blocks separated by blank lines (car-following gives
//! `P(s)` and `P(u|v)` in one file); lines starting with `#` are comments.
//!
//! ```text
//! v1,range,v2,probability
//! 29,40,29,0.00123
//! 29,45,29,0.00118
//! ```
//!
//! Every value of a key column must be a value of its grid axis (to within
//! a millionth of the axis step); points the table leaves out have
//! probability 0; a point given twice, a probability that is negative, NaN
//! or infinite, and a table of more than [`MAX_ROWS`] rows are refused with
//! the line and field. Errors name places as 1-based line and field
//! numbers, as an editor shows them.

use crate::ndd_table::TableError;

/// The most rows one block may hold (the car-following state grid has
/// 45,885 points; the paper's highway `(v₁, R, v₂)` grid 26,460).
pub const MAX_ROWS: usize = 1_000_000;

/// One block: its header and its rows, each with its line number.
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    /// The line of the header.
    pub line: usize,
    /// The column names, as given (trimmed, lower-case).
    pub columns: Vec<String>,
    /// `(line, values)` per row.
    pub rows: Vec<(usize, Vec<f64>)>,
}

/// The blocks of `text`, in order.
pub fn parse_blocks(text: &str) -> Result<Vec<Block>, TableError> {
    let mut blocks: Vec<Block> = Vec::new();
    let mut current: Option<Block> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let content = raw.trim_end_matches('\r').trim();
        if content.starts_with('#') {
            continue;
        }
        if content.is_empty() {
            blocks.extend(current.take());
            continue;
        }
        let fields: Vec<&str> = content.split(',').map(str::trim).collect();
        match &mut current {
            None => {
                let columns: Vec<String> = fields
                    .iter()
                    .map(|f| f.trim_matches('"').to_ascii_lowercase())
                    .collect();
                if let Some(k) = columns.iter().position(|c| c.parse::<f64>().is_ok()) {
                    return Err(TableError::HeaderNotNamed { line, field: k + 1 });
                }
                current = Some(Block {
                    line,
                    columns,
                    rows: Vec::new(),
                });
            }
            Some(block) => {
                if fields.len() != block.columns.len() {
                    return Err(TableError::WrongShape {
                        line,
                        expected: block.columns.len(),
                        actual: fields.len(),
                    });
                }
                if block.rows.len() == MAX_ROWS {
                    return Err(TableError::TooManyRows { max: MAX_ROWS });
                }
                let values = fields
                    .iter()
                    .enumerate()
                    .map(|(k, f)| number(f, line, k + 1))
                    .collect::<Result<Vec<_>, _>>()?;
                block.rows.push((line, values));
            }
        }
    }
    blocks.extend(current);
    if blocks.is_empty() {
        return Err(TableError::Empty);
    }
    Ok(blocks)
}

fn number(text: &str, line: usize, field: usize) -> Result<f64, TableError> {
    let trimmed = text.trim_matches('"').trim();
    trimmed.parse::<f64>().map_err(|_| TableError::NotNumeric {
        line,
        field,
        text: text.to_owned(),
    })
}

/// One key column of a block and the grid axis it indexes: values
/// `start + k · step`, `k = 0 … count − 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeyAxis<'a> {
    /// The column's name.
    pub column: &'a str,
    /// The axis' first value.
    pub start: f64,
    /// The step between values.
    pub step: f64,
    /// The number of values.
    pub count: usize,
}

impl KeyAxis<'_> {
    /// The index of `value` on the axis, when it is one of its values.
    fn index(&self, value: f64) -> Option<usize> {
        let k = ((value - self.start) / self.step).round();
        let on_grid = (value - (self.start + k * self.step)).abs() <= 1e-6 * self.step;
        (on_grid && k >= 0.0 && k < self.count as f64).then_some(k as usize)
    }

    fn describe(&self) -> String {
        let last = self.start + (self.count - 1) as f64 * self.step;
        format!(
            "{} to {} in steps of {}",
            crate::number::Num(self.start),
            crate::number::Num(last),
            crate::number::Num(self.step)
        )
    }
}

impl Block {
    /// Whether the block's columns are exactly `names` (in any order).
    pub fn has_columns(&self, names: &[&str]) -> bool {
        self.columns.len() == names.len()
            && names.iter().all(|n| self.columns.iter().any(|c| c == n))
    }

    fn column(&self, name: &str) -> usize {
        self.columns
            .iter()
            .position(|c| c == name)
            .expect("columns checked by has_columns")
    }

    /// The block's probabilities (column `probability`) laid out densely on
    /// the product of `axes` (row-major, the first axis slowest), with the
    /// sum of what was read. The block must have exactly the axes' columns
    /// and `probability` ([`Block::has_columns`]).
    pub fn dense(&self, axes: &[KeyAxis<'_>]) -> Result<(Vec<f64>, f64), TableError> {
        let keys: Vec<usize> = axes.iter().map(|a| self.column(a.column)).collect();
        let p = self.column("probability");
        let size: usize = axes.iter().map(|a| a.count).product();
        let mut dense = vec![0.0; size];
        let mut seen: Vec<u32> = vec![0; size];
        let mut sum = 0.0;
        for (line, values) in &self.rows {
            let mut index = 0;
            for (axis, &k) in axes.iter().zip(&keys) {
                let i = axis.index(values[k]).ok_or_else(|| TableError::OffGrid {
                    line: *line,
                    field: k + 1,
                    column: axis.column.to_owned(),
                    value: values[k],
                    axis: axis.describe(),
                })?;
                index = index * axis.count + i;
            }
            let value = values[p];
            if !value.is_finite() {
                return Err(TableError::NotFinite {
                    line: *line,
                    field: p + 1,
                    value,
                });
            }
            if value < 0.0 {
                return Err(TableError::Negative {
                    line: *line,
                    field: p + 1,
                    value,
                });
            }
            if seen[index] != 0 {
                return Err(TableError::Duplicate {
                    line: *line,
                    first: seen[index] as usize,
                });
            }
            seen[index] = *line as u32;
            dense[index] = value;
            sum += value;
        }
        Ok((dense, sum))
    }
}

/// The one block of `blocks` with exactly `columns`; `what` names it in the
/// error when none or several are there.
pub fn block_with<'b>(
    blocks: &'b [Block],
    columns: &[&str],
    what: &str,
) -> Result<&'b Block, TableError> {
    let mut found = blocks.iter().filter(|b| b.has_columns(columns));
    let first = found.next().ok_or_else(|| TableError::MissingBlock {
        what: what.to_owned(),
        columns: columns.join(","),
    })?;
    if let Some(second) = found.next() {
        return Err(TableError::DuplicateBlock {
            line: second.line,
            first: first.line,
        });
    }
    Ok(first)
}

/// Refuses a block whose header is none of `allowed`.
pub fn only_blocks(blocks: &[Block], allowed: &[&[&str]]) -> Result<(), TableError> {
    for b in blocks {
        if !allowed.iter().any(|cols| b.has_columns(cols)) {
            return Err(TableError::UnknownBlock {
                line: b.line,
                columns: b.columns.join(","),
                expected: allowed
                    .iter()
                    .map(|c| c.join(","))
                    .collect::<Vec<_>>()
                    .join("; "),
            });
        }
    }
    Ok(())
}

/// Checks a sum read from a table against 1: within the mass tolerance it
/// is renormalised (and the caller reports it), beyond it refused.
pub fn check_sum(sum: f64) -> Result<(), TableError> {
    let tolerance = crate::tolerance::MASS_SUM_TOLERANCE;
    if (sum - 1.0).abs() > tolerance {
        return Err(TableError::SumOff { sum, tolerance });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const AXES: [KeyAxis<'static>; 2] = [
        KeyAxis {
            column: "a",
            start: 0.0,
            step: 1.0,
            count: 3,
        },
        KeyAxis {
            column: "b",
            start: 10.0,
            step: 5.0,
            count: 2,
        },
    ];

    fn dense(text: &str) -> Result<(Vec<f64>, f64), TableError> {
        let blocks = parse_blocks(text)?;
        block_with(&blocks, &["a", "b", "probability"], "the test table")?.dense(&AXES)
    }

    #[test]
    fn a_block_lands_on_its_grid_in_any_column_order() {
        let (d, sum) = dense("# comment\nb,probability,a\n15,0.25,2\n10,0.75,0\n").unwrap();
        assert_eq!(d, vec![0.75, 0.0, 0.0, 0.0, 0.0, 0.25]);
        assert_eq!(sum, 1.0);
        // Two blocks, told apart by their columns.
        let blocks = parse_blocks("a,b,probability\n0,10,1\n\nx,probability\n1,1\n").unwrap();
        assert_eq!(blocks.len(), 2);
        assert!(block_with(&blocks, &["x", "probability"], "x").is_ok());
        assert!(only_blocks(&blocks, &[&["a", "b", "probability"]]).is_err());
    }

    #[test]
    fn each_problem_names_its_place() {
        let err = |text: &str| dense(text).unwrap_err().to_string();
        assert!(err("").contains("empty"));
        assert!(err("a,b,probability\n0,12,1\n")
            .contains("line 2, field 2: b = 12 is not on the grid (10 to 15 in steps of 5)"));
        assert!(err("a,b,probability\n0,10,-1\n").contains("line 2, field 3"));
        assert!(err("a,b,probability\n0,10,NaN\n").contains("must be finite"));
        assert!(err("a,b,probability\n0,10,x\n").contains("`x` is not a number"));
        assert!(err("a,b,probability\n0,10\n").contains("line 2 has 2 fields"));
        assert!(err("a,b,probability\n0,10,0.5\n0,10,0.5\n")
            .contains("line 3 gives the same point as line 2"));
        assert!(err("1,2,3\n").contains("line 1, field 1"));
        assert!(err("a,probability\n0,1\n").contains("a block with columns a,b,probability"));
        assert!(err("a,b,probability\n0,10,1\n\nb,a,probability\n0,10,1\n")
            .contains("line 4 repeats the block of line 1"));
        assert!(check_sum(0.9)
            .unwrap_err()
            .to_string()
            .contains("sum to 0.9"));
        assert!(check_sum(1.00001).is_ok());
    }
}

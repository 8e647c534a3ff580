//! Checking a vehicle model's parameters: the magnitudes every model
//! accepts, and the error that names the model, the parameter and the range
//! it must be in.

use thiserror::Error;

/// A parameter outside its valid range.
#[derive(Debug, Error, PartialEq)]
#[error("{model}: parameter `{parameter}` = {} {requirement}", crate::number::Num(*.value))]
pub struct ParamError {
    /// The model's name.
    pub model: &'static str,
    /// The parameter's name.
    pub parameter: &'static str,
    /// The value given.
    pub value: f64,
    /// The range it must be in, in words.
    pub requirement: &'static str,
}

/// The largest magnitude of any vehicle parameter in SI units (m, s, m/s,
/// m/s², gains): far beyond any real vehicle, small enough that no product
/// of a few parameters and states overflows.
pub const MAX_PARAMETER_MAGNITUDE: f64 = 1e4;
/// The smallest non-zero magnitude: below it a parameter is a rounding
/// error (a subnormal time constant or gain only breeds infinities).
pub const MIN_PARAMETER_MAGNITUDE: f64 = 1e-9;

/// Returns an error unless `value` is finite, 0 or of a magnitude in
/// `[MIN_PARAMETER_MAGNITUDE, MAX_PARAMETER_MAGNITUDE]`, and satisfies `ok`.
pub(crate) fn check(
    model: &'static str,
    parameter: &'static str,
    value: f64,
    ok: impl Fn(f64) -> bool,
    requirement: &'static str,
) -> Result<(), ParamError> {
    let magnitude = value.abs();
    let requirement = if !(value == 0.0
        || (MIN_PARAMETER_MAGNITUDE..=MAX_PARAMETER_MAGNITUDE).contains(&magnitude))
    {
        "must be 0 or between 1e-9 and 1e4 in magnitude (SI units)"
    } else if !ok(value) {
        requirement
    } else {
        return Ok(());
    };
    Err(ParamError {
        model,
        parameter,
        value,
        requirement,
    })
}

//! The command's output on stdout. A reader that goes away before the end
//! (`tslg campaign status 8 | head -3`) ends the command quietly, as Unix
//! tools do, where `println!` would panic on the broken pipe. The macros
//! reach every module declared after this one (`#[macro_use]` in lib.rs).

use std::io::{ErrorKind, Write};

/// Writes `args` to stdout; on a broken pipe, exits with status 0.
pub fn write(args: std::fmt::Arguments<'_>) {
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.flush()) {
        if e.kind() == ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        panic!("cannot write to stdout: {e}");
    }
}

/// `println!` through [`write`].
macro_rules! outln {
    () => {
        $crate::output::write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::output::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` through [`write`].
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::output::write(format_args!($($arg)*))
    };
}

/// A ratio with three significant digits and no more: 1.43, 0.0330, 686,
/// 8889 (`{:.0}` made 1.43 read "1" and 0.033 read "0").
pub fn ratio(r: f64) -> String {
    if !r.is_finite() || r == 0.0 {
        return format!("{r}");
    }
    let decimals = (2 - r.abs().log10().floor() as i32).max(0) as usize;
    format!("{r:.decimals$}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn ratios_keep_three_significant_digits() {
        let shown: Vec<String> = [1.4284, 0.03304, 686.2, 8889.4, 12.345, 1.0, 0.0]
            .map(super::ratio)
            .into();
        assert_eq!(
            shown,
            ["1.43", "0.0330", "686", "8889", "12.3", "1.00", "0"]
        );
    }
}

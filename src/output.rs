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

/// An error and its causes, joined by `: ` as `{:#}` joins them, without a
/// cause that only repeats what the text already ends with (sqlx's
/// database error and its SQLite source read the same:
/// `(code: 14) unable to open database file`, twice); a refused token
/// (401) also says which flag gives one.
pub fn error_text(error: &anyhow::Error) -> String {
    let mut text = chain_text(error);
    // A refused token is the CLI's to mend: say with which flag.
    let unauthorized = error.chain().any(|cause| {
        matches!(
            cause.downcast_ref::<tslg_client::CallError>(),
            Some(tslg_client::CallError::Refused { status: 401, .. })
        )
    });
    if unauthorized {
        text.push_str(
            " (give the coordinator's admin token with --token or TSLG_ADMIN_TOKEN; \
             a read token will do for reading)",
        );
    }
    text
}

/// The error and its causes, each said once.
fn chain_text(error: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in error.chain() {
        let part = cause.to_string();
        if text.is_empty() {
            text = part;
        } else if !text.ends_with(&part) {
            text.push_str(": ");
            text.push_str(&part);
        }
    }
    text
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_cause_that_repeats_the_text_is_said_once() {
        #[derive(Debug)]
        struct Database(std::io::Error);
        impl std::fmt::Display for Database {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "error returned from database: {}", self.0)
            }
        }
        impl std::error::Error for Database {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.0)
            }
        }
        let cause = std::io::Error::other("(code: 14) unable to open database file");
        let error = anyhow::Error::new(Database(cause)).context("cannot open the database x");
        assert_eq!(
            super::error_text(&error),
            "cannot open the database x: error returned from database: (code: 14) unable to \
             open database file"
        );
        // Distinct causes are all kept, as `{:#}` keeps them.
        let chained = anyhow::anyhow!("no such file").context("cannot read t.csv");
        assert_eq!(super::error_text(&chained), format!("{chained:#}"));
    }

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

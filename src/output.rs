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

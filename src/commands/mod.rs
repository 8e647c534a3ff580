//! One module per subcommand.

pub mod demo;
pub mod evaluate;
pub mod exact;
pub mod library;

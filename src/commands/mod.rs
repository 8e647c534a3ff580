//! One module per subcommand.

pub mod backup;
pub mod campaign;
pub mod cases;
pub mod demo;
pub mod evaluate;
pub mod events;
pub mod exact;
pub mod gate;
pub mod held_out;
pub mod library;
pub mod listing;
pub mod load;
pub mod local;
pub mod paired;
pub mod policy;
pub mod progress;
pub mod remote;
pub mod reproduce;
pub mod validate;
pub mod validate_method;
pub mod worker;

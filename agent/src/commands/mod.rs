//! One module per subcommand group.

pub mod data;
pub mod train;
pub mod report;
pub mod sample;

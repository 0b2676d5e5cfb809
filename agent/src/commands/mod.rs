//! One module per subcommand group.

pub mod bench;
pub mod data;
pub mod report;
pub mod sample;
pub mod train;

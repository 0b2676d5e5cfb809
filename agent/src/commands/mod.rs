//! One module per subcommand group.

pub mod bench;
pub mod bench_tasks;
pub mod data;
pub mod report;
pub mod run;
pub mod sample;
pub mod train;

//! One module per subcommand group, and the task command.

pub mod bench;
pub mod bench_retrieval;
pub mod bench_tasks;
pub mod data;
pub mod export;
pub mod flags;
pub mod generate;
pub mod load;
pub mod report;
pub mod retrieve;
pub mod run;
pub mod sample;
pub mod task;
pub mod train;

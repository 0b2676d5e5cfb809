//! One module per command (a subcommand group, or the task command): each parses its flags,
//! calls the library and prints; what several commands share is in [`crate::cli`].

pub mod bench;
pub mod bench_dno;
pub mod bench_retrieval;
pub mod bench_tasks;
pub mod data;
pub mod export;
pub mod report;
pub mod retrieve;
pub mod run;
pub mod sample;
pub mod task;
pub mod train;

//! What the commands share: flags and their checks, the generation options, the export choices,
//! the files every command loads, the one device, and progress on stderr.

pub mod export_formats;
pub mod flags;
pub mod generation_args;
pub mod load;
pub mod measure;
pub mod progress;
pub mod retrieval_task;

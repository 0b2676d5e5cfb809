//! The most a program may ask for.

/// Longest clip a program may ask for (frames at 20 fps; the prior itself stops at 196):
/// [`crate::limits::PROGRAM_FRAMES`], which the schema states too.
pub const MAX_FRAMES: u32 = crate::limits::PROGRAM_FRAMES.max as u32;

/// Most constraints in one program: [`crate::limits::PROGRAM_CONSTRAINTS`].
pub const MAX_CONSTRAINTS: usize = crate::limits::PROGRAM_CONSTRAINTS.max as usize;

/// Longest `text` or `description`: [`crate::limits::PROGRAM_TEXT_CHARS`].
pub const MAX_TEXT_CHARS: usize = crate::limits::PROGRAM_TEXT_CHARS.max as usize;

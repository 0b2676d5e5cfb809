//! Errors about a constraint program, each with the JSON path of the offending field.

/// A problem in a constraint program at `path`, written like `constraints[2].expr.args[1].height_m`
/// (empty for the whole document). The display form is what the LLM repair prompt receives.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {problem}", display_path(path))]
pub struct ProgramError {
    /// JSON path of the field, `serde_path_to_error` style.
    pub path: String,
    /// What is wrong.
    pub problem: Problem,
}

fn display_path(path: &str) -> &str {
    if path.is_empty() {
        "(document)"
    } else {
        path
    }
}

impl ProgramError {
    /// An error at `path`.
    pub fn new(path: impl Into<String>, problem: Problem) -> Self {
        ProgramError { path: path.into(), problem }
    }
}

/// What is wrong with a field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Problem {
    /// The text is not JSON.
    #[error("JSON syntax error at line {line}, column {column}: {message}")]
    Syntax {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// serde_json's message.
        message: String,
    },
    /// The JSON does not fit the program types (unknown joint, op or field, wrong type, negative
    /// count, empty list); serde's message, which lists the valid names.
    #[error("{0}")]
    Shape(String),
    /// The JSON violates the generated JSON Schema.
    #[error("violates the JSON Schema: {0}")]
    Schema(String),
    /// NaN or infinite.
    #[error("{} is not a finite number", short(*value))]
    NonFinite {
        /// The value.
        value: f64,
    },
    /// A number outside its sensible range.
    #[error("{} is outside [{}, {}]{}", short(*value), short(*min), short(*max), unit_suffix(unit))]
    OutOfRange {
        /// The value.
        value: f64,
        /// Smallest allowed value.
        min: f64,
        /// Largest allowed value.
        max: f64,
        /// Unit ("m", "m/s", or "" when dimensionless).
        unit: &'static str,
    },
    /// A frame reference outside the signal it indexes.
    #[error("frame {frame} is outside the clip: this signal has frames 0..={last}")]
    FrameOutsideClip {
        /// The frame, or the fraction's frame.
        frame: String,
        /// Last valid frame.
        last: u32,
    },
    /// A list that must not be empty.
    #[error("must not be empty")]
    Empty,
    /// A constraint id used twice.
    #[error("duplicate id `{0}`")]
    DuplicateId(String),
    /// An id that names no constraint.
    #[error("`{0}` names no constraint of this program")]
    UnknownId(String),
    /// Fields that contradict each other or the clip (explained in the message).
    #[error("{0}")]
    Inconsistent(String),
    /// A size over one of the [`crate::limits`].
    #[error("{0}")]
    OverLimit(#[from] crate::limits::LimitExceeded),
}

/// `value` as a person reads it: plain for ordinary magnitudes, scientific beyond (1e308 is
/// `1e308`, not 309 digits).
pub fn short(value: f64) -> String {
    let magnitude = value.abs();
    if value.is_finite() && value != 0.0 && !(1e-4..1e6).contains(&magnitude) {
        format!("{value:e}")
    } else {
        format!("{value}")
    }
}

fn unit_suffix(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

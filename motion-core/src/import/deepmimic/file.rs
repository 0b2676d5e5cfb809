//! The DeepMimic clip file read straight into 44-value rows, without a JSON tree: a `Value`
//! costs tens of bytes per number, a row 8, so memory follows the frames, not the text. Errors
//! name the frame and value (`frame 3, value 7: not a finite number`).

use serde::de::{Deserializer, Error as _, IgnoredAny, SeqAccess, Visitor};
use serde::Deserialize;

/// Values per frame.
pub(super) const FRAME_WIDTH: usize = 44;

/// A clip file as read: `Loop` and `Frames`; other keys are skipped.
#[derive(Deserialize)]
pub(super) struct ClipFile {
    /// `"wrap"`, `"none"`, or anything else (refused by the caller).
    #[serde(rename = "Loop")]
    pub(super) looping: Option<String>,
    /// The keyframes.
    #[serde(rename = "Frames")]
    pub(super) frames: Rows,
}

/// The `Frames` array, each row read into 44 values with messages naming the frame and value.
pub(super) struct Rows(pub(super) Vec<[f64; FRAME_WIDTH]>);

impl<'de> Deserialize<'de> for Rows {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_seq(RowsVisitor)
    }
}

struct RowsVisitor;

impl<'de> Visitor<'de> for RowsVisitor {
    type Value = Rows;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "an array of frames of {FRAME_WIDTH} numbers")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Rows, A::Error> {
        let mut rows = Vec::new();
        while let Some(row) = seq.next_element_seed(RowSeed(rows.len()))? {
            rows.push(row);
        }
        Ok(Rows(rows))
    }
}

/// Reads frame `.0` of `Frames`.
struct RowSeed(usize);

impl<'de> serde::de::DeserializeSeed<'de> for RowSeed {
    type Value = [f64; FRAME_WIDTH];

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for RowSeed {
    type Value = [f64; FRAME_WIDTH];

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "frame {}: an array of {FRAME_WIDTH} numbers", self.0)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut row = [0.0; FRAME_WIDTH];
        let mut found = 0;
        while let Some(Value(v)) = seq.next_element()? {
            let Some(v) = v else {
                return Err(A::Error::custom(format!("frame {}, value {found}: not a finite number", self.0)));
            };
            if let Some(slot) = row.get_mut(found) {
                *slot = v;
            }
            found += 1;
        }
        if found != FRAME_WIDTH {
            return Err(A::Error::custom(format!("frame {}: expected {FRAME_WIDTH} values, found {found}", self.0)));
        }
        Ok(row)
    }
}

/// One value of a row: `Some` for a finite number, `None` for anything else (skipped).
struct Value(Option<f64>);

impl<'de> Deserialize<'de> for Value {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_any(ValueVisitor)
    }
}

struct ValueVisitor;

impl<'de> Visitor<'de> for ValueVisitor {
    type Value = Value;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a number")
    }

    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        Ok(Value(Some(v).filter(|v| v.is_finite())))
    }

    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value(Some(v as f64)))
    }

    fn visit_u64<E>(self, v: u64) -> Result<Value, E> {
        Ok(Value(Some(v as f64)))
    }

    fn visit_bool<E>(self, _: bool) -> Result<Value, E> {
        Ok(Value(None))
    }

    fn visit_str<E>(self, _: &str) -> Result<Value, E> {
        Ok(Value(None))
    }

    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value(None))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        while seq.next_element::<IgnoredAny>()?.is_some() {}
        Ok(Value(None))
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        while map.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {}
        Ok(Value(None))
    }
}

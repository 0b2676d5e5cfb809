//! The length unit and up axis of a BVH file.

use glam::DVec3;

/// The length unit of a file's OFFSETs and positions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LengthUnit {
    /// Metres.
    Metres,
    /// Centimetres (Mixamo, most MotionBuilder exports, Boxing_Toes).
    Centimetres,
    /// Millimetres.
    Millimetres,
    /// Inches.
    Inches,
    /// CMU's ASF length unit, 1/0.45 inch = 0.056444 m, kept by the cgspeed BVH conversion.
    CmuAsf,
    /// An explicit scale: metres per file unit (positive).
    MetresPer(f64),
}

/// Stature used to pick a unit: candidates are compared by |ln(height / this)|.
const TYPICAL_STATURE_M: f64 = 1.7;
/// Rest heights outside this range after scaling are reported (m).
pub(super) const PLAUSIBLE_STATURE_M: (f64, f64) = (1.0, 2.3);

impl LengthUnit {
    /// Units tried by [`LengthUnit::detect`].
    pub const DETECTABLE: [LengthUnit; 5] =
        [LengthUnit::Metres, LengthUnit::Centimetres, LengthUnit::Millimetres, LengthUnit::Inches, LengthUnit::CmuAsf];

    /// Metres per file unit.
    pub fn metres(self) -> f64 {
        match self {
            LengthUnit::Metres => 1.0,
            LengthUnit::Centimetres => 0.01,
            LengthUnit::Millimetres => 0.001,
            LengthUnit::Inches => 0.0254,
            LengthUnit::CmuAsf => 0.0254 / 0.45,
            LengthUnit::MetresPer(m) => m,
        }
    }

    /// The unit of [`LengthUnit::DETECTABLE`] under which a skeleton `rest_height` file units tall
    /// is closest to 1.7 m (by ratio); `None` for a flat or non-finite skeleton. A CMU/cgspeed
    /// skeleton (about 25 units, T-pose with splayed legs) comes out as [`LengthUnit::CmuAsf`].
    pub fn detect(rest_height: f64) -> Option<LengthUnit> {
        if !(rest_height.is_finite() && rest_height > 0.0) {
            return None;
        }
        let miss = |u: &LengthUnit| (rest_height * u.metres() / TYPICAL_STATURE_M).ln().abs();
        LengthUnit::DETECTABLE.into_iter().min_by(|a, b| miss(a).total_cmp(&miss(b)))
    }
}

/// The file's up axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpAxis {
    /// Y up (the BVH norm): axes are used as they are.
    #[default]
    Y,
    /// Z up, character facing −y: `(x, y, z) → (x, z, −y)`.
    Z,
}

impl UpAxis {
    /// A file-axes vector in our axes.
    pub fn to_ours(self, v: DVec3) -> DVec3 {
        match self {
            UpAxis::Y => v,
            UpAxis::Z => DVec3::new(v.x, v.z, -v.y),
        }
    }
}

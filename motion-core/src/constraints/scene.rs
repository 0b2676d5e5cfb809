//! Scene primitives as per-point errors: points `[B, T, P, 3]` → `[B, T, P]` (m, or m² for the
//! balance beam). Formulas are documented on [`Primitive`]'s variants. Gates (`z_range_m`,
//! `x_range_m`, a beam's `extent_m`) test each point's own coordinate without gradient, as
//! ProgMoGen's if-else frame selection does.

use candle_core::{Result, Tensor, D};

use super::geometry::{constant, cross, dot, norm, unit};
use crate::program::{BalanceBeam, Gap, Ground, Hurdle, InsideBox, OverheadBarrier, Primitive, Wall};

/// The primitive's error per point, `[B, T, P]` (≥ 0). With `physical` the clearance margins
/// are ignored: the error is then the penetration depth into the obstacle itself.
pub fn primitive_error(points: &Tensor, primitive: &Primitive, physical: bool) -> Result<Tensor> {
    let coord = |i: usize| points.narrow(D::Minus1, i, 1).and_then(|c| c.squeeze(D::Minus1));
    let margin = |m: f64| if physical { 0.0 } else { m };
    match primitive {
        Primitive::Gap(Gap { centre_x_m, width_m, margin_m, z_range_m }) => {
            let half = width_m / 2.0 - margin(*margin_m);
            let error = ((coord(0)? - *centre_x_m)?.abs()? - half)?.relu()?;
            gate(error, &coord(2)?, *z_range_m)
        }
        Primitive::OverheadBarrier(OverheadBarrier { underside_height_m, margin_m, z_range_m, x_range_m }) => {
            let error = (coord(1)? - (underside_height_m - margin(*margin_m)))?.relu()?;
            gate(gate(error, &coord(2)?, Some(*z_range_m))?, &coord(0)?, *x_range_m)
        }
        Primitive::Hurdle(Hurdle { height_m, margin_m, z_range_m, x_range_m }) => {
            let error = ((height_m + margin(*margin_m)) - coord(1)?)?.relu()?;
            gate(gate(error, &coord(2)?, Some(*z_range_m))?, &coord(0)?, *x_range_m)
        }
        Primitive::Ground(Ground { height_m }) => (*height_m - coord(1)?)?.relu(),
        Primitive::InsideBox(InsideBox { x_range_m, y_range_m, z_range_m }) => {
            let mut error = coord(0)?.zeros_like()?;
            for (axis, range) in [x_range_m, y_range_m, z_range_m].into_iter().enumerate() {
                if let Some([lo, hi]) = range {
                    let c = coord(axis)?;
                    error = ((error + (*lo - &c)?.relu()?)? + (c - *hi)?.relu()?)?;
                }
            }
            Ok(error)
        }
        Primitive::Wall(Wall { point_m, normal, margin_m }) => {
            let origin = constant(point_m, points.dtype(), points.device())?;
            let n = constant(&unit(*normal), points.dtype(), points.device())?;
            let signed = dot(&points.broadcast_sub(&origin)?, &n)?;
            (margin(*margin_m) - signed)?.relu()
        }
        Primitive::BalanceBeam(BalanceBeam { point_m, direction, half_width_m, horizontal, extent_m }) => {
            // On a horizontal beam every point, the beam and its direction are dropped onto the
            // ground plane (y = 0), so the distance is measured in x and z only.
            let (offset, direction) = if *horizontal {
                let flat = constant(&[1.0, 0.0, 1.0], points.dtype(), points.device())?;
                let origin = constant(&[point_m[0], 0.0, point_m[2]], points.dtype(), points.device())?;
                (points.broadcast_mul(&flat)?.broadcast_sub(&origin)?, [direction[0], 0.0, direction[2]])
            } else {
                (points.broadcast_sub(&constant(point_m, points.dtype(), points.device())?)?, *direction)
            };
            let d = constant(&unit(direction), points.dtype(), points.device())?;
            let error = (norm(&cross(&offset, &d)?)? - *half_width_m)?.relu()?.sqr()?;
            match extent_m {
                Some(_) => gate(error, &dot(&offset, &d)?, *extent_m),
                None => Ok(error),
            }
        }
    }
}

/// Whether the primitive is an obstacle whose penetration depth is a metric (RG-DNO's Max SP);
/// the balance beam is a target, not an obstacle.
pub fn is_obstacle(primitive: &Primitive) -> bool {
    !matches!(primitive, Primitive::BalanceBeam(_))
}

/// Zeroes the error of points whose coordinate `c` (`[B, T, P]`: z, x, or the position along a
/// beam) lies outside `range` (strictly inside counts); no gradient flows through the gate.
fn gate(error: Tensor, c: &Tensor, range: Option<[f64; 2]>) -> Result<Tensor> {
    let Some([lo, hi]) = range else { return Ok(error) };
    let c = c.detach();
    let inside = (c.gt(lo)?.to_dtype(error.dtype())? * c.lt(hi)?.to_dtype(error.dtype())?)?;
    error * inside
}

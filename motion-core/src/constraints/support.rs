//! The feet's support region and the signed distance of the projected centre of mass to it
//! (ProgMoGen §3.2's centre-of-mass constraint).
//!
//! The region is the convex hull, on the ground plane (x, z), of the supporting feet's ankle and
//! foot joints, grown by [`FOOT_HALF_WIDTH_M`] (the joints lie on the foot's centre line). The hull
//! is found per frame without gradient; its edges are then built from the joint positions, so
//! the distance is differentiable in the joints and the centre of mass. The signed distance is
//! `max_e n̂_e · (q − p_e) − FOOT_HALF_WIDTH_M` over the hull's edges e (outward normals): exact
//! inside and on the sides, a slight under-estimate near the corners outside. A one-foot region
//! is a segment; its "edges" are its two sides and two end caps.

use candle_core::{DType, Result, Tensor, D};

use super::geometry::NORM_EPS;
use crate::program::Support;
use crate::skeleton::Joint;

/// Half the width of a foot around the line through its ankle and foot joints, m.
pub const FOOT_HALF_WIDTH_M: f64 = 0.05;

/// Edges per frame: a quadrilateral's 4, or a segment's 2 sides and 2 caps (a triangle repeats
/// one edge).
const EDGES: usize = 4;

/// The joints spanning the support region.
pub fn support_joints(support: Support) -> &'static [Joint] {
    match support {
        Support::BothFeet => &[Joint::LeftAnkle, Joint::LeftFoot, Joint::RightAnkle, Joint::RightFoot],
        Support::LeftFoot => &[Joint::LeftAnkle, Joint::LeftFoot],
        Support::RightFoot => &[Joint::RightAnkle, Joint::RightFoot],
    }
}

/// One edge: the normal is `(p[to] − p[from])`, turned by −90° on the ground plane when
/// `turn` (outward for a counter-clockwise hull), normalised, and anchored at `p[base]`.
#[derive(Debug, Clone, Copy)]
struct Edge {
    base: u32,
    from: u32,
    to: u32,
    turn: bool,
}

/// Signed distance `[B, T]` (m, > 0 outside) of `q` `[B, T, 2]` (x, z) to the region spanned by
/// the support points `[B, T, S, 2]` (x, z).
pub fn signed_distance(q: &Tensor, support: &Tensor) -> Result<Tensor> {
    let (batch, frames, count, _) = support.dims4()?;
    let values = support.detach().to_dtype(DType::F64)?.reshape((batch * frames, count * 2))?.to_vec2::<f64>()?;
    let mut base = Vec::with_capacity(batch * frames * EDGES);
    let mut from = Vec::with_capacity(batch * frames * EDGES);
    let mut to = Vec::with_capacity(batch * frames * EDGES);
    let mut turn = Vec::with_capacity(batch * frames * EDGES);
    for frame in &values {
        let points: Vec<[f64; 2]> = frame.chunks_exact(2).take(count).map(|c| [c[0], c[1]]).collect();
        for edge in hull_edges(&points) {
            base.push(edge.base);
            from.push(edge.from);
            to.push(edge.to);
            turn.push(u8::from(edge.turn));
        }
    }
    let device = support.device();
    let index = |v: Vec<u32>| -> Result<Tensor> {
        Tensor::from_vec(v, (batch, frames, EDGES, 1), device)?.repeat((1, 1, 1, 2))?.contiguous()
    };
    let gather = |i: &Tensor| support.contiguous()?.gather(i, 2); // [B, T, E, 2]
    let (p_base, p_from, p_to) = (gather(&index(base)?)?, gather(&index(from)?)?, gather(&index(to)?)?);
    let e = (p_to - p_from)?;
    let (eu, ev) = (e.narrow(D::Minus1, 0, 1)?, e.narrow(D::Minus1, 1, 1)?);
    let turned = Tensor::cat(&[ev.clone(), eu.neg()?], D::Minus1)?;
    let turn = Tensor::from_vec(turn, (batch, frames, EDGES, 1), device)?.repeat((1, 1, 1, 2))?;
    let normal = turn.where_cond(&turned, &e)?;
    let length = (normal.sqr()?.sum_keepdim(D::Minus1)? + NORM_EPS)?.sqrt()?;
    let normal = normal.broadcast_div(&length)?;
    let offset = q.unsqueeze(2)?.broadcast_sub(&p_base)?;
    (offset * normal)?.sum(D::Minus1)?.max(D::Minus1)? - FOOT_HALF_WIDTH_M
}

/// The edges of the convex hull of `points` (x, z), [`EDGES`] of them.
fn hull_edges(points: &[[f64; 2]]) -> [Edge; EDGES] {
    let hull = convex_hull(points);
    let segment = |a: u32, b: u32| {
        [
            Edge { base: a, from: a, to: b, turn: true },
            Edge { base: a, from: b, to: a, turn: true },
            Edge { base: b, from: a, to: b, turn: false },
            Edge { base: a, from: b, to: a, turn: false },
        ]
    };
    match hull.as_slice() {
        [] => segment(0, 0),
        [a] => segment(*a, *a),
        [a, b] => segment(*a, *b),
        vertices => {
            let edge = |k: usize| {
                let (a, b) = (vertices[k % vertices.len()], vertices[(k + 1) % vertices.len()]);
                Edge { base: a, from: a, to: b, turn: true }
            };
            let first = edge(0);
            [first, edge(1), edge(2), if vertices.len() > 3 { edge(3) } else { first }]
        }
    }
}

/// Indices of the convex hull's vertices in counter-clockwise order in the (x, z) plane (with
/// x to the right and z up), without collinear points (Andrew's monotone chain).
fn convex_hull(points: &[[f64; 2]]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    order.sort_by(|&a, &b| {
        let (p, q) = (points[a as usize], points[b as usize]);
        p[0].total_cmp(&q[0]).then(p[1].total_cmp(&q[1]))
    });
    let cross = |o: u32, a: u32, b: u32| {
        let (o, a, b) = (points[o as usize], points[a as usize], points[b as usize]);
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<u32> = Vec::with_capacity(2 * points.len());
    for pass in 0..2 {
        let start = hull.len();
        let sequence: Box<dyn Iterator<Item = &u32>> =
            if pass == 0 { Box::new(order.iter()) } else { Box::new(order.iter().rev()) };
        for &p in sequence {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 1e-12 {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull.dedup();
    if hull.len() >= 2 && hull.first() == hull.last() {
        hull.pop();
    }
    hull
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::finite_difference_check;
    use candle_core::Device;

    fn t(values: &[[f64; 2]]) -> Tensor {
        let flat: Vec<f64> = values.iter().flatten().copied().collect();
        Tensor::from_vec(flat, (1, 1, values.len(), 2), &Device::Cpu).unwrap()
    }

    fn q(x: f64, z: f64) -> Tensor {
        Tensor::new(&[[[x, z]]], &Device::Cpu).unwrap()
    }

    fn distance(point: Tensor, support: &Tensor) -> f64 {
        signed_distance(&point, support).unwrap().flatten_all().unwrap().to_vec1::<f64>().unwrap()[0]
    }

    #[test]
    fn square_of_feet_by_hand() {
        // Feet: a 0.4 × 0.2 rectangle (x from −0.2 to 0.2, z from 0 to 0.2).
        let feet = t(&[[0.2, 0.0], [0.2, 0.2], [-0.2, 0.0], [-0.2, 0.2]]);
        // Centre: 0.1 from the nearest side, minus the foot half-width.
        assert!((distance(q(0.0, 0.1), &feet) - (-0.1 - FOOT_HALF_WIDTH_M)).abs() < 1e-9);
        // 0.3 in front of the front edge.
        assert!((distance(q(0.0, 0.5), &feet) - (0.3 - FOOT_HALF_WIDTH_M)).abs() < 1e-9);
        // 0.1 to the left of the left side.
        assert!((distance(q(0.3, 0.1), &feet) - (0.1 - FOOT_HALF_WIDTH_M)).abs() < 1e-9);
    }

    #[test]
    fn one_foot_is_a_segment_with_caps() {
        let foot = t(&[[0.0, 0.0], [0.0, 0.15]]);
        assert!((distance(q(0.0, 0.05), &foot) + FOOT_HALF_WIDTH_M).abs() < 1e-9, "on the foot line");
        assert!((distance(q(0.2, 0.05), &foot) - (0.2 - FOOT_HALF_WIDTH_M)).abs() < 1e-9, "beside");
        assert!((distance(q(0.0, 0.45), &foot) - (0.3 - FOOT_HALF_WIDTH_M)).abs() < 1e-9, "ahead");
        assert!((distance(q(0.0, -0.1), &foot) - (0.1 - FOOT_HALF_WIDTH_M)).abs() < 1e-9, "behind");
    }

    #[test]
    fn hull_drops_interior_and_collinear_points() {
        let hull = convex_hull(&[[0.0, 0.0], [1.0, 0.0], [0.5, 0.2], [0.5, 1.0]]);
        assert_eq!(hull.len(), 3);
        assert!(!hull.contains(&2));
        assert_eq!(convex_hull(&[[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]]), vec![0, 2]);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let feet = t(&[[0.21, 0.01], [0.19, 0.22], [-0.2, -0.01], [-0.18, 0.2]]);
        let point = q(0.05, 0.45);
        finite_difference_check(&feet, |s| signed_distance(&point, s)?.sum_all(), 1e-6, 1e-5).unwrap();
        finite_difference_check(&point, |p| signed_distance(p, &feet)?.sum_all(), 1e-6, 1e-5).unwrap();
    }
}

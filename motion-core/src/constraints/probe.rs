//! A fixed probe motion and the check that a program's loss can be optimised on it: ProgMoGen's
//! GPT-written losses sometimes had no gradient with respect to the motion, which silently
//! stalls the optimiser.

use candle_core::{DType, Device, Result, Tensor, Var};

use super::compiled::CompiledProgram;
use crate::skeleton::{FPS, NUM_JOINTS};

/// A standing pose (m, y up, facing +z, +x left), hand-placed, in joint index order.
pub const STANDING: [[f64; 3]; NUM_JOINTS] = [
    [0.0, 0.9, 0.0],    // pelvis
    [0.1, 0.85, 0.0],   // left_hip
    [-0.1, 0.85, 0.0],  // right_hip
    [0.0, 1.0, 0.0],    // spine1
    [0.1, 0.5, 0.0],    // left_knee
    [-0.1, 0.5, 0.0],   // right_knee
    [0.0, 1.15, 0.0],   // spine2
    [0.1, 0.1, 0.0],    // left_ankle
    [-0.1, 0.1, 0.0],   // right_ankle
    [0.0, 1.25, 0.0],   // spine3
    [0.1, 0.02, 0.12],  // left_foot
    [-0.1, 0.02, 0.12], // right_foot
    [0.0, 1.45, 0.0],   // neck
    [0.08, 1.4, 0.0],   // left_collar
    [-0.08, 1.4, 0.0],  // right_collar
    [0.0, 1.6, 0.02],   // head
    [0.18, 1.4, 0.0],   // left_shoulder
    [-0.18, 1.4, 0.0],  // right_shoulder
    [0.2, 1.12, 0.0],   // left_elbow
    [-0.2, 1.12, 0.0],  // right_elbow
    [0.22, 0.87, 0.0],  // left_wrist
    [-0.22, 0.87, 0.0], // right_wrist
];

/// The probe: [`STANDING`] gliding along +z at 1 m/s with a small smooth sway (±3 cm, a
/// different phase per joint and axis, so no distance or comparison sits exactly on a tie),
/// `[1, frames, 22, 3]` f64.
pub fn probe_motion(frames: usize, device: &Device) -> Result<Tensor> {
    let mut data = Vec::with_capacity(frames * NUM_JOINTS * 3);
    for t in 0..frames {
        let time = t as f64 / FPS;
        for (j, joint) in STANDING.iter().enumerate() {
            for (axis, &value) in joint.iter().enumerate() {
                let phase = (j * 3 + axis) as f64 * 0.7;
                let sway = 0.03 * (std::f64::consts::TAU * 0.9 * time + phase).sin();
                let glide = if axis == 2 { time } else { 0.0 };
                data.push(value + glide + sway);
            }
        }
    }
    Tensor::from_vec(data, (1, frames, NUM_JOINTS, 3), device)
}

/// The outcome of [`CompiledProgram::gradient_check`].
#[derive(Debug, Clone, PartialEq)]
pub struct GradientCheck {
    /// `Σ wᵢ·Eᵢ` on the probe.
    pub total: f64,
    /// ‖∂total/∂joints‖₂ on the probe.
    pub gradient_norm: f64,
    /// Constraints with a positive error on the probe but no gradient (ids).
    pub stalled: Vec<String>,
}

impl GradientCheck {
    /// Whether an optimiser can make progress: the loss is 0 already, or it has a gradient.
    pub fn passes(&self) -> bool {
        self.total == 0.0 || self.gradient_norm > 0.0
    }
}

/// Largest counting sharpness used by [`CompiledProgram::gradient_check`], per unit of the
/// signal. At RG-DNO's T = 10⁴ the sigmoids saturate away from the counted events by design
/// (RG-DNO starts near them by retrieval), which is not what the check is after.
pub const PROBE_SHARPNESS: f64 = 10.0;

impl CompiledProgram {
    /// Evaluates the program on the probe motion (its own initial motion: `stay_near_initial`
    /// terms are 0) and measures the gradient of the total and of every constraint. Counting
    /// sigmoids are softened to `PROBE_SHARPNESS`, so what fails is a loss that does not
    /// depend on the motion where it is violated, e.g. a distance between two fixed points.
    pub fn gradient_check(&self) -> Result<GradientCheck> {
        let device = Device::Cpu;
        let probe = Var::from_tensor(&probe_motion(self.frames(), &device)?)?;
        let evaluation = self
            .with_sharpness_at_most(PROBE_SHARPNESS)
            .evaluate(probe.as_tensor(), Some(&probe.as_tensor().detach()))
            .map_err(candle_core::Error::wrap)?;
        let norm = |loss: &Tensor| -> Result<f64> {
            let grads = loss.sum_all()?.backward()?;
            match grads.get(probe.as_tensor()) {
                Some(g) => g.sqr()?.sum_all()?.sqrt()?.to_dtype(DType::F64)?.to_scalar::<f64>(),
                None => Ok(0.0),
            }
        };
        let scalar = |t: &Tensor| -> Result<f64> { t.sum_all()?.to_dtype(DType::F64)?.to_scalar::<f64>() };
        let mut stalled = Vec::new();
        for (id, error) in &evaluation.per_constraint {
            if scalar(error)? > 0.0 && norm(error)? == 0.0 {
                stalled.push(id.clone());
            }
        }
        Ok(GradientCheck { total: scalar(&evaluation.total)?, gradient_norm: norm(&evaluation.total)?, stalled })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::TaskProgram;

    fn check(expr: &str) -> GradientCheck {
        let text = format!(r#"{{"text": "", "frames": 40, "constraints": [{{"id": "c1", "expr": {expr}}}]}}"#);
        let program = TaskProgram::from_json(&text).unwrap();
        CompiledProgram::compile(&program, &Device::Cpu).unwrap().gradient_check().unwrap()
    }

    #[test]
    fn optimisable_satisfied_and_stalled_losses() {
        let reach = check(
            r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [5.0], "frames": {"keyframes": ["last"]}}"#,
        );
        assert!(reach.passes() && reach.total > 0.0 && reach.gradient_norm > 0.0 && reach.stalled.is_empty());
        let satisfied = check(
            r#"{"op": "less_than", "quantity": {"kind": "position", "of": {"joint": "head"}, "axes": "y"}, "max": 5.0}"#,
        );
        assert!(satisfied.passes() && satisfied.total == 0.0);
        // Counting far from any event still has a gradient once softened for the probe.
        let touches = check(
            r#"{"op": "count", "signals": [{"kind": "distance", "a": {"joint": "left_wrist"}, "b": {"fixed_m": [0.0, 2.1, 0.3]}, "axes": "xyz"}], "extremum": "valleys", "threshold": 0.1, "target_count": 3}"#,
        );
        assert!(touches.passes() && touches.total > 0.0 && touches.stalled.is_empty(), "{touches:?}");
        // A distance between two fixed points does not depend on the motion.
        let stalled = check(
            r#"{"op": "equal", "quantity": {"kind": "distance", "a": {"fixed_m": [0.0, 0.0, 0.0]}, "b": {"fixed_m": [1.0, 0.0, 0.0]}, "axes": "xyz"}, "target": [0.0]}"#,
        );
        assert!(!stalled.passes(), "{stalled:?}");
        assert_eq!(stalled.stalled, vec!["c1".to_owned()]);
    }
}

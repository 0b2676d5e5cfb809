//! The optimiser every loop shares (training, DNO, RG-DNO's soft blend, the IK baselines, the
//! kinematic refinement): AdamW (Loshchilov & Hutter 2019) whose moments can be saved and
//! restored, which candle's optimiser does not allow.

use candle_core::backprop::GradStore;
use candle_core::{Result, Tensor, Var};

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPS: f64 = 1e-8;

/// AdamW over a fixed list of variables (β = 0.9, 0.999; ε = 1e-8).
pub struct AdamW {
    vars: Vec<Var>,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
    steps: usize,
    weight_decay: f64,
}

impl AdamW {
    /// Zero moments.
    pub fn new(vars: Vec<Var>, weight_decay: f64) -> Result<Self> {
        let m = vars.iter().map(|v| v.as_tensor().zeros_like()).collect::<Result<Vec<_>>>()?;
        let v = m.clone();
        Ok(Self { vars, m, v, steps: 0, weight_decay })
    }

    /// One update with learning rate `lr`. A variable without a gradient is an error: every
    /// parameter of the denoiser must receive one.
    pub fn step(&mut self, grads: &GradStore, lr: f64) -> Result<()> {
        self.steps += 1;
        let bc1 = 1.0 - BETA1.powi(self.steps as i32);
        let bc2 = 1.0 - BETA2.powi(self.steps as i32);
        for ((var, m), v) in self.vars.iter().zip(self.m.iter_mut()).zip(self.v.iter_mut()) {
            let g = grads.get(var.as_tensor()).ok_or_else(|| {
                candle_core::Error::Msg(format!("no gradient for a variable of shape {:?}", var.shape()))
            })?;
            *m = ((&*m * BETA1)? + (g * (1.0 - BETA1))?)?;
            *v = ((&*v * BETA2)? + (g.sqr()? * (1.0 - BETA2))?)?;
            let update = ((&*m / bc1)? / ((&*v / bc2)?.sqrt()? + EPS)?)?;
            let decayed = (var.as_tensor().detach() * (1.0 - lr * self.weight_decay))?;
            var.set(&(decayed - (update * lr)?)?)?;
        }
        Ok(())
    }

    /// Updates done.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// First and second moments, in variable order.
    pub fn moments(&self) -> (&[Tensor], &[Tensor]) {
        (&self.m, &self.v)
    }

    /// Restores moments and the step count (from a checkpoint).
    pub fn restore(&mut self, m: Vec<Tensor>, v: Vec<Tensor>, steps: usize) -> Result<()> {
        if m.len() != self.vars.len() || v.len() != self.vars.len() {
            candle_core::bail!(
                "optimizer state has {} / {} moments for {} variables",
                m.len(),
                v.len(),
                self.vars.len()
            );
        }
        for ((var, m), v) in self.vars.iter().zip(&m).zip(&v) {
            if m.shape() != var.shape() || v.shape() != var.shape() {
                candle_core::bail!("optimizer moment shape {:?} does not match variable {:?}", m.shape(), var.shape());
            }
        }
        self.m = m;
        self.v = v;
        self.steps = steps;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn minimises_a_quadratic() {
        let x = Var::new(&[3.0f32, -2.0], &Device::Cpu).unwrap();
        let mut opt = AdamW::new(vec![x.clone()], 0.0).unwrap();
        for _ in 0..500 {
            let loss = x.as_tensor().sqr().unwrap().sum_all().unwrap();
            opt.step(&loss.backward().unwrap(), 0.05).unwrap();
        }
        let v = x.as_tensor().to_vec1::<f32>().unwrap();
        assert!(v.iter().all(|x| x.abs() < 1e-2), "{v:?}");
    }
}

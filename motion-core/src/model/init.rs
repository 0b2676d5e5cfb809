//! Seeded, PyTorch-style parameter initialisation into a [`VarMap`] (candle's own CPU RNG
//! cannot be seeded, so `VarBuilder::from_varmap` would give unrepeatable weights).

use std::sync::Mutex;

use candle_core::{bail, DType, Device, Error, Result, Shape, Tensor, Var};
use candle_nn::var_builder::SimpleBackend;
use candle_nn::{Init, VarMap};
use rand::rngs::StdRng;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// A [`SimpleBackend`] that returns the variable already in `varmap` under a name, or creates
/// it from the init hint with a seeded RNG (in the order the model requests them).
pub(crate) struct SeededInit {
    varmap: VarMap,
    rng: Mutex<StdRng>,
}

impl SeededInit {
    pub fn new(varmap: VarMap, rng: StdRng) -> Self {
        Self { varmap, rng: Mutex::new(rng) }
    }

    fn sample(&self, shape: &Shape, init: Init) -> Result<Vec<f64>> {
        let n = shape.elem_count();
        let mut rng = self.rng.lock().map_err(|_| Error::Msg("init RNG lock poisoned".into()))?;
        Ok(match init {
            Init::Const(c) => vec![c; n],
            Init::Uniform { lo, up } => (0..n).map(|_| lo + (up - lo) * rng.random::<f64>()).collect(),
            Init::Randn { mean, stdev } => (0..n)
                .map(|_| {
                    let z: f64 = StandardNormal.sample(&mut *rng);
                    mean + stdev * z
                })
                .collect(),
            other => bail!("seeded init does not support {other:?}"),
        })
    }
}

impl SimpleBackend for SeededInit {
    fn get(&self, shape: Shape, name: &str, init: Init, dtype: DType, dev: &Device) -> Result<Tensor> {
        if let Some(existing) = self.lookup(name)? {
            if existing.shape() != &shape {
                bail!("{name}: stored shape {:?}, model expects {shape:?}", existing.shape());
            }
            return existing.to_dtype(dtype)?.to_device(dev);
        }
        let values = self.sample(&shape, init)?;
        let var = Var::from_tensor(&Tensor::from_vec(values, shape, dev)?.to_dtype(dtype)?)?;
        let tensor = var.as_tensor().clone();
        self.varmap.data().lock().map_err(|_| Error::Msg("VarMap lock poisoned".into()))?.insert(name.to_string(), var);
        Ok(tensor)
    }

    fn get_unchecked(&self, name: &str, dtype: DType, dev: &Device) -> Result<Tensor> {
        match self.lookup(name)? {
            Some(t) => t.to_dtype(dtype)?.to_device(dev),
            None => bail!("{name} is not in the VarMap"),
        }
    }

    fn contains_tensor(&self, name: &str) -> bool {
        self.lookup(name).ok().flatten().is_some()
    }
}

/// The variables of `varmap` behind named parameters (a model's, in its order), each with its
/// name: what an optimiser steps.
pub(crate) fn named_vars(varmap: &VarMap, named: &[(String, Tensor)]) -> Result<Vec<(String, Var)>> {
    let data = varmap.data().lock().map_err(|_| Error::Msg("VarMap lock poisoned".into()))?;
    named
        .iter()
        .map(|(name, _)| {
            data.get(name)
                .cloned()
                .map(|v| (name.clone(), v))
                .ok_or_else(|| Error::Msg(format!("no variable for `{name}`")))
        })
        .collect()
}

impl SeededInit {
    fn lookup(&self, name: &str) -> Result<Option<Tensor>> {
        let data = self.varmap.data().lock().map_err(|_| Error::Msg("VarMap lock poisoned".into()))?;
        Ok(data.get(name).map(|v| v.as_tensor().clone()))
    }
}

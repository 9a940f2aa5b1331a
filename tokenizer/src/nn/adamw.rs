//! AdamW (Loshchilov and Hutter) with global-norm gradient clipping and a state that can be saved,
//! so training resumes exactly where it stopped.

use super::params::Params;
use candle_core::backprop::GradStore;
use candle_core::{Device, Result, Tensor};
use std::collections::{BTreeMap, HashMap};

/// Optimiser settings.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub struct AdamWConfig {
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Added to the root of the second moment.
    pub eps: f64,
    /// Decoupled weight decay per step, as a fraction of the learning rate.
    pub weight_decay: f64,
    /// Gradients are scaled down when their global L2 norm exceeds this.
    pub clip_norm: f64,
}

impl Default for AdamWConfig {
    fn default() -> Self {
        AdamWConfig { beta1: 0.9, beta2: 0.99, eps: 1e-8, weight_decay: 0.0, clip_norm: 1.0 }
    }
}

/// AdamW over every variable of a [`Params`].
pub struct AdamW {
    config: AdamWConfig,
    moments: BTreeMap<String, (Tensor, Tensor)>,
    step: u64,
}

impl AdamW {
    /// A fresh optimiser (moments zero).
    pub fn new(params: &Params, config: AdamWConfig) -> Result<AdamW> {
        let mut moments = BTreeMap::new();
        for (name, var) in params.vars() {
            moments.insert(name.clone(), (var.zeros_like()?, var.zeros_like()?));
        }
        Ok(AdamW { config, moments, step: 0 })
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// One update at learning rate `lr`; returns the gradients' global norm before clipping.
    /// Variables without a gradient are left alone.
    pub fn step(&mut self, params: &Params, grads: &GradStore, lr: f64) -> Result<f64> {
        let mut squared = 0.0f64;
        let mut present = Vec::new();
        for (name, var) in params.vars() {
            if let Some(g) = grads.get(var.as_tensor()) {
                squared += g.sqr()?.sum_all()?.to_scalar::<f32>()? as f64;
                present.push((name, var, g));
            }
        }
        let norm = squared.sqrt();
        let scale = if norm > self.config.clip_norm { self.config.clip_norm / norm } else { 1.0 };
        self.step += 1;
        let c = self.config;
        let t = self.step as i32;
        let (bias1, bias2) = (1.0 - c.beta1.powi(t), 1.0 - c.beta2.powi(t));
        for (name, var, g) in present {
            // Detached: a gradient's op graph reaches back into the step's forward pass, and the
            // moments would otherwise keep every step's graph alive.
            let g = (g.detach() * scale)?;
            let (m, v) = self.moments.get_mut(name).expect("every variable has moments");
            *m = ((&*m * c.beta1)? + (&g * (1.0 - c.beta1))?)?.detach();
            *v = ((&*v * c.beta2)? + (g.sqr()? * (1.0 - c.beta2))?)?.detach();
            let update = ((&*m / bias1)? / ((&*v / bias2)?.sqrt()? + c.eps)?)?;
            let decayed = (var.as_tensor().detach() * (1.0 - lr * c.weight_decay))?;
            var.set(&(decayed - (update * lr)?)?.detach())?;
        }
        Ok(norm)
    }

    /// The moments (`m/NAME`, `v/NAME`) and the step count (`step`), by name.
    pub fn tensors(&self) -> Result<HashMap<String, Tensor>> {
        let mut map = HashMap::new();
        for (name, (m, v)) in &self.moments {
            map.insert(format!("m/{name}"), m.clone());
            map.insert(format!("v/{name}"), v.clone());
        }
        map.insert("step".to_string(), Tensor::new(&[self.step as f64], &Device::Cpu)?);
        Ok(map)
    }

    /// Restores what [`AdamW::tensors`] gave, for the same parameters.
    pub fn assign(&mut self, map: &HashMap<String, Tensor>) -> Result<()> {
        for (name, (m, v)) in self.moments.iter_mut() {
            match (map.get(&format!("m/{name}")), map.get(&format!("v/{name}"))) {
                (Some(sm), Some(sv)) if sm.dims() == m.dims() => {
                    *m = sm.clone();
                    *v = sv.clone();
                }
                _ => candle_core::bail!("the optimiser state does not match parameter {name}"),
            }
        }
        let Some(step) = map.get("step") else { candle_core::bail!("the optimiser state has no step count") };
        self.step = step.to_vec1::<f64>()?[0] as u64;
        Ok(())
    }
}

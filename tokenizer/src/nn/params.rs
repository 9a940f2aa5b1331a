//! Named trainable parameters, initialised from a seeded generator and saved as safetensors.

use candle_core::{DType, Device, Result, Tensor, Var};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// A model's parameters by name. Names are `/`-separated paths (`encoder/block0/attn/qkv/w`);
/// the order is the names' order, so an optimiser's state lines up across runs.
pub struct Params {
    vars: BTreeMap<String, Var>,
    buffers: BTreeMap<String, Tensor>,
    prefix: Vec<String>,
    rng: ChaCha8Rng,
}

impl Params {
    /// An empty store whose initial values come from `seed`.
    pub fn new(seed: u64) -> Params {
        Params {
            vars: BTreeMap::new(),
            buffers: BTreeMap::new(),
            prefix: Vec::new(),
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Runs `build` with `name` appended to the path of every parameter it creates.
    pub fn scope<T>(&mut self, name: &str, build: impl FnOnce(&mut Params) -> T) -> T {
        self.prefix.push(name.to_string());
        let out = build(self);
        self.prefix.pop();
        out
    }

    fn full_name(&self, name: &str) -> String {
        let mut path = self.prefix.join("/");
        if !path.is_empty() {
            path.push('/');
        }
        path.push_str(name);
        path
    }

    fn insert(&mut self, name: &str, tensor: Tensor) -> Result<Tensor> {
        let full = self.full_name(name);
        assert!(!self.vars.contains_key(&full), "parameter {full} is created twice");
        let var = Var::from_tensor(&tensor)?;
        let t = var.as_tensor().clone();
        self.vars.insert(full, var);
        Ok(t)
    }

    /// A parameter drawn from N(0, std²).
    pub fn normal(&mut self, name: &str, shape: &[usize], std: f32) -> Result<Tensor> {
        let count = shape.iter().product();
        let dist = Normal::new(0.0f32, std).expect("a finite standard deviation");
        let values: Vec<f32> = (0..count).map(|_| dist.sample(&mut self.rng)).collect();
        let t = Tensor::from_vec(values, shape, &Device::Cpu)?;
        self.insert(name, t)
    }

    /// A parameter filled with one value.
    pub fn constant(&mut self, name: &str, shape: &[usize], value: f32) -> Result<Tensor> {
        let t = Tensor::full(value, shape, &Device::Cpu)?;
        self.insert(name, t)
    }

    /// The trainable variables in name order.
    pub fn vars(&self) -> impl Iterator<Item = (&String, &Var)> {
        self.vars.iter()
    }

    /// Number of scalar parameters.
    pub fn count(&self) -> usize {
        self.vars.values().map(|v| v.elem_count()).sum()
    }

    /// Sets a non-trainable tensor saved with the parameters (codebooks, statistics).
    pub fn set_buffer(&mut self, name: &str, tensor: Tensor) {
        self.buffers.insert(name.to_string(), tensor);
    }

    /// Every parameter and buffer by name.
    pub fn tensors(&self) -> HashMap<String, Tensor> {
        let mut map: HashMap<String, Tensor> =
            self.vars.iter().map(|(k, v)| (k.clone(), v.as_tensor().clone())).collect();
        map.extend(self.buffers.iter().map(|(k, t)| (k.clone(), t.clone())));
        map
    }

    /// Writes every parameter and buffer to a safetensors file.
    pub fn save(&self, path: &Path) -> Result<()> {
        candle_core::safetensors::save(&self.tensors(), path)
    }

    /// Overwrites every parameter with the file's value of the same name; a parameter missing from
    /// the file or of another shape is an error (a checkpoint of another configuration). Returns
    /// the file's other tensors (buffers such as codebooks, or parts of a larger model).
    pub fn load(&mut self, path: &Path) -> Result<HashMap<String, Tensor>> {
        let tensors = candle_core::safetensors::load(path, &Device::Cpu)?;
        self.assign(tensors)
    }

    /// Overwrites parameters from named tensors and returns the rest (see [`Params::load`]).
    pub fn assign(&mut self, mut tensors: HashMap<String, Tensor>) -> Result<HashMap<String, Tensor>> {
        for (name, var) in &self.vars {
            let Some(t) = tensors.remove(name) else {
                candle_core::bail!("the checkpoint has no parameter {name}");
            };
            if t.dims() != var.dims() {
                candle_core::bail!("parameter {name} is {:?} in the checkpoint but {:?} here", t.dims(), var.dims());
            }
            var.set(&t.to_dtype(DType::F32)?)?;
        }
        Ok(tensors)
    }
}

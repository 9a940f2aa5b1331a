//! The training machinery on a small synthetic skeleton: every trainable variable of every model
//! receives a gradient (candle's fused layers silently drop them), the optimiser's state
//! round-trips, and the quantiser behaves as residual VQ should.

use anymo_motion::bvh::parse_str;
use anymo_motion::motion::Motion;
use anymo_tokenizer::dataset::{LoaderConfig, TrainingClip, WindowLoader};
use anymo_tokenizer::nn::{AdamW, AdamWConfig, Params, snapshot};
use anymo_tokenizer::owo::graph::{GraphBatch, NODE_INPUT_DIM, SkeletonGraph};
use anymo_tokenizer::owo::pretrain::{Heads, Targets, losses};
use anymo_tokenizer::owo::{Owo, OwoConfig};
use anymo_tokenizer::tat::objective::{LossWeights, Prepared, RootStats, loss};
use anymo_tokenizer::tat::rvq::{Rvq, RvqConfig};
use anymo_tokenizer::tat::temporal::Upsampling;
use anymo_tokenizer::tat::{Baseline, BaselineConfig, Codec, Fusion, Representation, Tat, TatConfig, TokenizerConfig};
use anymo_tokenizer::text::EMBEDDING_DIM;
use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn walker(frames: usize) -> Motion {
    let mut text = String::from(
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n \
         JOINT LeftUpLeg\n {\n  OFFSET 0.2 0 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  JOINT LeftLeg\n  {\n   OFFSET 0 -0.5 0\n   CHANNELS 3 Zrotation Xrotation Yrotation\n   End Site\n   {\n    OFFSET 0 -0.5 0\n   }\n  }\n }\n \
         JOINT RightUpLeg\n {\n  OFFSET -0.2 0 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  JOINT RightLeg\n  {\n   OFFSET 0 -0.5 0\n   CHANNELS 3 Zrotation Xrotation Yrotation\n   End Site\n   {\n    OFFSET 0 -0.5 0\n   }\n  }\n }\n \
         JOINT Spine\n {\n  OFFSET 0 0.3 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 0.3 0\n  }\n }\n}\nMOTION\n",
    );
    text.push_str(&format!("Frames: {frames}\nFrame Time: 0.0333333\n"));
    for f in 0..frames {
        let a = (f as f32 * 0.2).sin() * 30.0;
        text.push_str(&format!(
            "0 1 {} 0 0 {} 0 {a} 0 0 {} 0 0 {} 0 0 {} 0 0 5 0\n",
            f as f32 * 0.02,
            a * 0.1,
            -a,
            -a,
            a.abs()
        ));
    }
    Motion::from_bvh(&parse_str(&text).unwrap())
}

/// A graph with made-up text features (the real ones come from the sentence encoder).
fn graph_of(motion: &Motion) -> SkeletonGraph {
    let j = motion.skeleton().len();
    let node_text = (0..j * NODE_INPUT_DIM).map(|k| ((k * 7919) % 97) as f32 / 97.0 - 0.5).collect();
    SkeletonGraph {
        parents: motion.skeleton().parents().collect(),
        offsets: motion.skeleton().joints().iter().map(|j| j.offset).collect(),
        node_text,
        labels: (0..j).map(|i| format!("label {}", i % 4)).collect(),
    }
}

fn assert_every_variable_learns(params: &Params, grads: &candle_core::backprop::GradStore) {
    for (name, var) in params.vars() {
        let g = grads.get(var.as_tensor()).unwrap_or_else(|| panic!("{name} receives no gradient"));
        let norm = g.sqr().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap();
        assert!(norm > 0.0 && norm.is_finite(), "{name} has gradient norm {norm}");
    }
}

fn small_rvq() -> RvqConfig {
    RvqConfig { layers: 3, codes: 16, dim: 16, dropout: 0.0, ..RvqConfig::default() }
}

fn batch() -> anymo_tokenizer::dataset::Batch {
    let config = LoaderConfig { window: 16, batch_size: 4, ..LoaderConfig::default() };
    let clips = [walker(40), walker(33)].map(|motion| TrainingClip { motion, source: "walks".into() });
    WindowLoader::new(clips.to_vec(), config).step(0).unwrap().remove(0)
}

#[test]
fn every_owo_variable_receives_a_gradient() {
    let mut params = Params::new(1);
    let config = OwoConfig { dim: 16, blocks: 2, heads: 2, freqs: 2 };
    let owo = Owo::new(&mut params, config).unwrap();
    let heads = Heads::new(&mut params, 16).unwrap();
    let g = graph_of(&walker(2));
    let global = vec![0.1f32; EMBEDDING_DIM];
    let batch = GraphBatch::new(&[&g, &g], &global, config.freqs).unwrap();
    let targets = Targets::new(&[&g, &g], &batch, Some(8), &mut ChaCha8Rng::seed_from_u64(0));
    let (parts, _) = losses(&owo, &heads, &batch, &targets, 0.1).unwrap();
    let total = ((&parts[0] + &parts[1]).unwrap() + &parts[2]).unwrap();
    assert_every_variable_learns(&params, &total.backward().unwrap());
}

fn tat(fusion: Fusion) -> Tat {
    let mut owo_params = Params::new(0);
    let owo = OwoConfig { dim: 16, blocks: 2, heads: 2, freqs: 2 };
    let config = TokenizerConfig {
        tat: TatConfig {
            dim: 16,
            heads: 2,
            ff: 32,
            blocks: 1,
            spatial_layers: 1,
            condition_dim: 16 + 6 * 2,
            fusion,
            upsampling: Upsampling::Interpolate,
        },
        rvq: small_rvq(),
        owo,
        offset_freqs: 2,
        window: 16,
        overlap: 4,
        root: RootStats { mean: [0.0; 4], std: [1.0; 4] },
        weights: LossWeights::default(),
        representation: Representation::Reference,
    };
    Tat::new(config, 3, &mut owo_params, vec![0.1; EMBEDDING_DIM]).unwrap()
}

#[test]
fn every_tat_and_baseline_variable_receives_a_gradient() {
    let b = batch();
    let graph = graph_of(&walker(2));
    let stats = RootStats { mean: [0.0; 4], std: [1.0; 4] };
    let prepared = Prepared::new(&b, &stats).unwrap();
    let baseline = Baseline::new(
        BaselineConfig {
            max_joints: 8,
            dim: 16,
            blocks: 1,
            upsampling: Upsampling::Interpolate,
            rvq: small_rvq(),
            root: stats,
            weights: LossWeights::default(),
            representation: Representation::Reference,
        },
        5,
    )
    .unwrap();
    let codecs: Vec<Box<dyn Codec>> =
        vec![Box::new(tat(Fusion::Film)), Box::new(tat(Fusion::Additive)), Box::new(baseline)];
    for mut codec in codecs {
        let out = codec.reconstruct(&prepared, &graph, true, &mut ChaCha8Rng::seed_from_u64(0)).unwrap();
        let (total, _) = loss(&out.prediction, &prepared, &stats, &out.commitment, &LossWeights::default()).unwrap();
        assert_every_variable_learns(codec.params(), &total.backward().unwrap());
    }
}

#[test]
fn optimiser_state_round_trips_and_resumes_exactly() {
    let dir = std::env::temp_dir().join(format!("anymo-adamw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |steps: usize, split: Option<usize>| -> Vec<f32> {
        let mut params = Params::new(9);
        let w = params.normal("w", &[4, 3], 1.0).unwrap();
        let mut opt = AdamW::new(&params, AdamWConfig::default()).unwrap();
        let x = Tensor::from_vec((0..8).map(|v| v as f32 * 0.1).collect::<Vec<_>>(), (2, 4), &Device::Cpu).unwrap();
        for step in 0..steps {
            if split == Some(step) {
                let path = dir.join("state.safetensors");
                snapshot::save(&path, &params, &opt, "{}").unwrap();
                let mut fresh = Params::new(1234);
                let _ = fresh.normal("w", &[4, 3], 1.0).unwrap();
                let mut fresh_opt = AdamW::new(&fresh, AdamWConfig::default()).unwrap();
                let (_, buffers) = snapshot::load(&path, &mut fresh, &mut fresh_opt).unwrap();
                assert!(buffers.is_empty());
                assert_eq!(fresh_opt.steps(), step as u64);
                params = fresh;
                opt = fresh_opt;
            }
            let w = params.vars().next().unwrap().1.as_tensor().clone();
            let loss = x.matmul(&w).unwrap().sqr().unwrap().sum_all().unwrap();
            opt.step(&params, &loss.backward().unwrap(), 0.01).unwrap();
        }
        let _ = &w;
        params.vars().next().unwrap().1.flatten_all().unwrap().to_vec1().unwrap()
    };
    assert_eq!(run(6, None), run(6, Some(3)));
}

#[test]
fn residual_quantisation_reconstructs_its_own_codes() {
    let mut rvq = Rvq::new(small_rvq());
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let x = Tensor::from_vec(
        (0..64 * 16).map(|k| ((k * 31) % 17) as f32 / 17.0).collect::<Vec<_>>(),
        (64, 16),
        &Device::Cpu,
    )
    .unwrap();
    // Training steps seed and then follow the data.
    for _ in 0..5 {
        rvq.forward(&x, true, &mut rng).unwrap();
    }
    let q = rvq.forward(&x, false, &mut rng).unwrap();
    assert_eq!(q.codes.len(), 64);
    assert!(q.codes.iter().all(|c| c.len() == 3));
    // Decoding the codes gives the quantised latent the forward pass produced.
    let decoded: Vec<f32> = rvq.decode(&q.codes).unwrap().flatten_all().unwrap().to_vec1().unwrap();
    let latent: Vec<f32> = q.latent.flatten_all().unwrap().to_vec1().unwrap();
    for (a, b) in decoded.iter().zip(&latent) {
        assert!((a - b).abs() < 1e-5);
    }
    // The data has 17 distinct values per position and at most 16 codes, so the residual after
    // three layers must be much smaller than the data.
    let error = (q.latent - &x).unwrap().sqr().unwrap().mean_all().unwrap().to_scalar::<f32>().unwrap();
    let scale = x.sqr().unwrap().mean_all().unwrap().to_scalar::<f32>().unwrap();
    assert!(error < 0.05 * scale, "residual {error} vs signal {scale}");
}

//! A TAT training step's achieved FLOP/s against this machine's dense matmul rate, measured in
//! the same run with the same threads. The step's FLOPs are its matmuls' (forward as recorded by
//! `nn::flops`, backward counted as twice the forward); element-wise work is not counted, so the
//! figure is a lower bound on the work done.
//!
//! `cargo bench -p anymo-tokenizer --bench train_step` (RAYON_NUM_THREADS sets the threads).

use anymo_motion::bvh::parse_str;
use anymo_motion::motion::Motion;
use anymo_tokenizer::dataset::{LoaderConfig, TrainingClip, WindowLoader};
use anymo_tokenizer::nn::{AdamW, AdamWConfig, Params, flops};
use anymo_tokenizer::owo::graph::{NODE_INPUT_DIM, SkeletonGraph};
use anymo_tokenizer::tat::objective::{Prepared, RootStats, loss};
use anymo_tokenizer::tat::{Codec, Fusion, Representation, Tat, TokenizerConfig};
use anymo_tokenizer::text::EMBEDDING_DIM;
use rand::SeedableRng;
use std::time::Instant;

/// A 22-joint humanoid (the corpus' most common rig size) walking in place.
fn humanoid(frames: usize) -> Motion {
    let mut text = String::from(
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n",
    );
    let mut channels = 6;
    let chains: [(&str, [f32; 3], usize); 5] = [
        ("LeftLeg", [0.1, -0.1, 0.0], 5),
        ("RightLeg", [-0.1, -0.1, 0.0], 5),
        ("Spine", [0.0, 0.1, 0.0], 3),
        ("LeftArm", [0.1, 0.3, 0.0], 4),
        ("RightArm", [-0.1, 0.3, 0.0], 4),
    ];
    for (name, o, len) in chains {
        for k in 0..len {
            text.push_str(&format!(
                " JOINT {name}{k}\n {{\n  OFFSET {} {} {}\n  CHANNELS 3 Zrotation Xrotation Yrotation\n",
                o[0], o[1], o[2]
            ));
            channels += 3;
        }
        text.push_str("  End Site\n  {\n   OFFSET 0 -0.1 0\n  }\n");
        for _ in 0..len {
            text.push_str(" }\n");
        }
    }
    text.push_str(&format!("}}\nMOTION\nFrames: {frames}\nFrame Time: 0.0333333\n"));
    for f in 0..frames {
        let row: Vec<String> = (0..channels)
            .map(|c| format!("{:.3}", ((f * 7 + c * 13) % 40) as f32 - 20.0 + if c == 1 { 21.0 } else { 0.0 }))
            .collect();
        text.push_str(&row.join(" "));
        text.push('\n');
    }
    Motion::from_bvh(&parse_str(&text).expect("a valid humanoid"))
}

fn main() {
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "all cores".into());
    let motion = humanoid(64);
    let joints = motion.skeleton().len();
    let clips = (0..16).map(|_| TrainingClip { motion: motion.clone(), source: "humanoid".into() }).collect();
    let loader = WindowLoader::new(clips, LoaderConfig { window: 64, batch_size: 16, ..LoaderConfig::default() });
    let batch = loader.step(0).unwrap().remove(0);
    let stats = RootStats { mean: [0.0; 4], std: [1.0; 4] };
    let config = TokenizerConfig::new(stats, Fusion::Film, Representation::Reference);
    let mut owo_params = Params::new(0);
    let mut tat = Tat::new(config, 0, &mut owo_params, vec![0.1; EMBEDDING_DIM]).unwrap();
    let graph = SkeletonGraph {
        parents: motion.skeleton().parents().collect(),
        offsets: motion.skeleton().joints().iter().map(|j| j.offset).collect(),
        node_text: vec![0.05; joints * NODE_INPUT_DIM],
        labels: (0..joints).map(|j| j.to_string()).collect(),
    };
    let mut optimiser = AdamW::new(tat.params(), AdamWConfig::default()).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    // Seconds spent in the forward pass (with the loss), the backward pass and the optimiser.
    let mut phases = [0f64; 3];
    let mut step = |tat: &mut Tat, phases: &mut [f64; 3]| {
        let t = Instant::now();
        let prepared = Prepared::new(&batch, &stats).unwrap();
        let out = tat.reconstruct(&prepared, &graph, true, &mut rng).unwrap();
        let (total, _) =
            loss(&out.prediction, &prepared, &stats, &out.commitment, &tat.config().weights.clone()).unwrap();
        phases[0] += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let grads = total.backward().unwrap();
        phases[1] += t.elapsed().as_secs_f64();
        let t = Instant::now();
        optimiser.step(tat.params(), &grads, 1e-4).unwrap();
        phases[2] += t.elapsed().as_secs_f64();
    };
    step(&mut tat, &mut [0.0; 3]);
    flops::take();
    let steps = 5;
    let t = Instant::now();
    for _ in 0..steps {
        step(&mut tat, &mut phases);
    }
    let seconds = t.elapsed().as_secs_f64() / steps as f64;
    let step_flops = 3.0 * flops::take() as f64 / steps as f64;
    let step_rate = step_flops / seconds;
    let reference = flops::dense_matmul_rate().unwrap();
    println!("threads: {threads}; batch: 16 windows x 64 frames x {joints} joints; TAT default configuration");
    println!("training step: {:.3} s, {:.2} GFLOP (matmuls, forward + backward)", seconds, step_flops / 1e9);
    let [forward, backward, optimiser] = phases.map(|p| p / steps as f64);
    println!("  forward and loss {forward:.3} s, backward {backward:.3} s, optimiser {optimiser:.3} s");
    println!("achieved: {:.1} GFLOP/s", step_rate / 1e9);
    println!("dense 1024x1024 f32 matmul, same run: {:.1} GFLOP/s", reference / 1e9);
    println!("ratio: {:.1}% of the machine's matmul rate (goal: 35%)", 100.0 * step_rate / reference);
}

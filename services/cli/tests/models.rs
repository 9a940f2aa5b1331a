//! The model commands end to end on a small sample of the real corpus: a tiny OwO pretraining,
//! tokenizer and baseline trainings (one of them killed and resumed, which must end exactly
//! where an uninterrupted run ends, and one continued from its shipped checkpoint), the
//! evaluation, and tokenize / detokenize / transfer on real files with the output keeping the
//! target's hierarchy.

use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::motion::Motion;
use anymo_tests::{
    data_dir, gunzip, models_dir, safetensors_values as tensors, scratch_dir, succeeded as ok, wait_for_saved_step,
};
use std::path::Path;
use std::process::Command;

fn anymo(models: &Path, args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_anymo"));
    c.args(args).env("ANYMO_MODELS", models).env("RAYON_NUM_THREADS", "1");
    c
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// A joint as the output must keep it: name, parent, offset, channels.
type JointShape = (String, Option<usize>, [f32; 3], Vec<String>);

fn hierarchy(path: &Path) -> Vec<JointShape> {
    let clip = bvh::read_path(path, ReadOptions::default()).unwrap();
    clip.skeleton()
        .joints()
        .iter()
        .map(|j| {
            (
                j.name.clone(),
                j.parent,
                j.offset.to_array(),
                j.channels.as_slice().iter().map(|c| format!("{c:?}")).collect(),
            )
        })
        .collect()
}

#[test]
fn tiny_training_resumes_exactly_evaluates_and_transfers() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let dir = scratch_dir("models");
    let manifest = shared.join("manifest.tsv");
    let (manifest, ck) = (manifest.to_str().unwrap(), dir.join("ck"));
    let ck = ck.to_str().unwrap();
    let run = |name: &str| dir.join("runs").join(name).to_string_lossy().into_owned();
    let common = |name: &str| -> Vec<String> {
        ["--manifest", manifest, "--limit", "6", "--out-dir", ck, "--run-dir", &run(name)].map(String::from).to_vec()
    };
    let with = |base: Vec<String>, more: &[&str]| -> Vec<String> {
        base.into_iter().chain(more.iter().map(|s| s.to_string())).collect()
    };

    let owo = with(with(vec!["train".into(), "owo".into()], &strs(&common("owo"))), &["--steps", "3"]);
    ok(anymo(&models, &strs(&owo)).output().unwrap());
    let card: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("ck/owo.json")).unwrap()).unwrap();
    assert_eq!(card["steps"], 3);
    assert!(card["metrics"]["zero_shot_skeletons"]["lca_accuracy"].as_f64().is_some());

    // The same tiny TAT run twice: once straight through, once killed after a saved step.
    let tat = |name: &str| {
        with(
            with(vec!["train".into(), "tokenizer".into()], &strs(&common(name))),
            &["--variant", "tat", "--name", name, "--steps", "6", "--batch-size", "4", "--save-every", "0"],
        )
    };
    ok(anymo(&models, &strs(&tat("straight"))).output().unwrap());
    let mut child = anymo(&models, &strs(&tat("killed"))).stderr(std::process::Stdio::null()).spawn().unwrap();
    wait_for_saved_step(&dir.join("runs/killed/state.safetensors"), 2);
    child.kill().unwrap();
    child.wait().unwrap();
    let resumed = ok(anymo(&models, &strs(&tat("killed"))).output().unwrap());
    assert!(String::from_utf8_lossy(&resumed.stderr).contains("resuming at step"), "the second run resumed");
    let (a, b) = (tensors(&dir.join("ck/straight.safetensors")), tensors(&dir.join("ck/killed.safetensors")));
    assert_eq!(a.len(), b.len());
    for ((na, va), (nb, vb)) in a.iter().zip(&b) {
        assert_eq!(na, nb);
        assert!(va == vb, "{na} differs between the straight and the resumed run");
    }

    // Continuing the shipped checkpoint: it starts at its 6 steps, ends at the new total, and
    // its card says where it came from. A total it has reached, or another model shape, is refused.
    let more = |steps: &str, extra: &[&str]| {
        let base = with(vec!["train".into(), "tokenizer".into()], &strs(&common("straight-more")));
        let args =
            ["--variant", "tat", "--name", "straight", "--steps", steps, "--batch-size", "4", "--continue-shipped"];
        with(with(base, &args), extra)
    };
    let continued = ok(anymo(&models, &strs(&more("8", &[]))).output().unwrap());
    assert!(String::from_utf8_lossy(&continued.stderr).contains("continuing straight from step 6"));
    let card: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("ck/straight.json")).unwrap()).unwrap();
    assert_eq!((card["steps"].as_u64(), card["config"]["training"]["start"].as_u64()), (Some(8), Some(6)));
    assert!(card["command"].as_str().unwrap().contains("--steps 6 --batch-size 4 --save-every 0 && "), "{card}");
    let after = tensors(&dir.join("ck/straight.safetensors"));
    assert!(a.iter().zip(&after).any(|((_, before), (_, now))| before != now), "training went on");
    let again = anymo(&models, &strs(&more("8", &[]))).output().unwrap();
    assert!(String::from_utf8_lossy(&again.stderr).contains("has 8 steps already"), "{again:?}");
    let other = anymo(&models, &strs(&more("10", &["--codes", "512"]))).output().unwrap();
    assert!(String::from_utf8_lossy(&other.stderr).contains("another configuration"), "{other:?}");
    // Loss weights and augmentation shape the run, not the model: a continued run may change
    // them, and its card records the new ones.
    ok(anymo(&models, &strs(&more("10", &["--weight", "rotation=2", "--weight", "heading=1", "--rebase", "0.25"])))
        .output()
        .unwrap());
    let card: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("ck/straight.json")).unwrap()).unwrap();
    assert_eq!(card["config"]["tokenizer"]["weights"]["rotation"].as_f64(), Some(2.0), "{card}");
    assert_eq!(card["config"]["tokenizer"]["weights"]["heading"].as_f64(), Some(1.0), "{card}");
    assert_eq!(card["config"]["training"]["rebase"].as_f64(), Some(0.25), "{card}");
    assert_eq!(card["config"]["training"]["start"].as_u64(), Some(8));

    let baseline = with(
        with(vec!["train".into(), "tokenizer".into()], &strs(&common("baseline"))),
        &["--variant", "baseline", "--steps", "3", "--batch-size", "4", "--width", "32"],
    );
    ok(anymo(&models, &strs(&baseline)).output().unwrap());
    let card: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("ck/baseline.json")).unwrap()).unwrap();
    assert_eq!(card["config"]["baseline"]["dim"].as_u64(), Some(32), "{card}");
    // The width is the baseline's: TAT refuses it rather than ignore it.
    let tat_width = anymo(&models, &["train", "tokenizer", "--variant", "tat", "--width", "32"]).output().unwrap();
    assert!(!tat_width.status.success());
    let said = String::from_utf8_lossy(&tat_width.stderr);
    assert!(said.contains("--width sets the baseline's trunk"), "{said}");
    let results = dir.join("eval.json");
    ok(anymo(
        &models,
        &[
            "eval",
            "tokenizer",
            "--manifest",
            manifest,
            "--limit",
            "3",
            "--dir",
            ck,
            "--models",
            "straight,baseline",
            "--json",
            results.to_str().unwrap(),
        ],
    )
    .output()
    .unwrap());
    let results: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&results).unwrap()).unwrap();
    for model in ["straight", "baseline"] {
        for split in ["test", "zero-shot"] {
            let m = &results[model][split];
            assert_eq!(m["clips"], 3, "{model} {split}");
            let mpjpe = m["mpjpe"].as_f64().unwrap();
            assert!(mpjpe.is_finite() && mpjpe > 0.0, "{model} {split}: {mpjpe}");
            let yaw = m["mpjpe_yaw"].as_f64().unwrap();
            assert!(yaw.is_finite() && yaw > 0.0, "{model} {split}: {yaw}");
        }
    }
    // The static reference keeps the true root, so its MPJPE with translation is its
    // root-aligned one, anchors change nothing for it, and it moves no joint, so it has an error.
    for split in ["test", "zero-shot"] {
        let m = &results["static pose (reference)"][split];
        assert_eq!(m["clips"], 3, "{split}");
        let (plain, trans, yaw) =
            (m["mpjpe"].as_f64().unwrap(), m["mpjpe_trans"].as_f64().unwrap(), m["mpjpe_yaw"].as_f64().unwrap());
        assert!(plain > 0.0 && (plain - trans).abs() < 1e-6, "{split}: {plain} {trans}");
        assert!((plain - m["mpjpe_free"].as_f64().unwrap()).abs() < 1e-9, "{split}: {m}");
        assert!(yaw.is_finite() && yaw > 0.0, "{split}: {yaw}");
        // By joint kind: the true root has no error; the joints held still that move others do.
        assert!(m["geodist_root"].as_f64().unwrap().abs() < 1e-3, "{split}: {m}");
        assert!(m["geodist_inner"].as_f64().unwrap() > 0.0, "{split}: {m}");
    }

    // Tokens and transfer with the tiny checkpoint: the output keeps the target's hierarchy.
    let source = dir.join("walk.bvh");
    gunzip(&shared.join("bandai/dataset-1/dataset-1_walk_normal_001.bvh.gz"), &source);
    let horse_gz = anymo_tests::files_with_suffix(&shared.join("quaternius/bvh"), ".bvh.gz")
        .into_iter()
        .find(|p| p.to_string_lossy().contains("Horse"))
        .expect("a horse clip");
    let horse = dir.join("horse.bvh");
    gunzip(&horse_gz, &horse);
    let tokens = dir.join("walk.tokens.json");
    let model = ["--checkpoints", ck, "--model", "straight"];
    ok(anymo(
        &models,
        &strs(&with(
            vec!["tokenize".into(), source.to_string_lossy().into(), "-o".into(), tokens.to_string_lossy().into()],
            &model,
        )),
    )
    .output()
    .unwrap());
    let file: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&tokens).unwrap()).unwrap();
    let frames = file["tokens"]["frames"].as_u64().unwrap() as usize;
    let steps: usize = file["tokens"]["codes"].as_array().unwrap().iter().map(|w| w.as_array().unwrap().len()).sum();
    assert_eq!(steps, 16 * file["tokens"]["starts"].as_array().unwrap().len(), "16 token steps per 64-frame window");
    let back = dir.join("walk.back.bvh");
    let detok = with(
        vec![
            "detokenize".into(),
            tokens.to_string_lossy().into(),
            "--skeleton".into(),
            source.to_string_lossy().into(),
            "-o".into(),
            back.to_string_lossy().into(),
        ],
        &model,
    );
    ok(anymo(&models, &strs(&detok)).output().unwrap());
    assert_eq!(hierarchy(&back), hierarchy(&source));
    assert_eq!(bvh::read_path(&back, ReadOptions::default()).unwrap().frames(), frames);
    // The root is anchored at every window start and the last frame: there the decoded root
    // stands where the source's does, although six training steps decode little else.
    let anchored: Vec<usize> =
        file["tokens"]["anchors"].as_array().unwrap().iter().map(|a| a["frame"].as_u64().unwrap() as usize).collect();
    let mut expected: Vec<usize> =
        file["tokens"]["starts"].as_array().unwrap().iter().map(|s| s.as_u64().unwrap() as usize).collect();
    expected.push(frames - 1);
    assert_eq!(anchored, expected);
    let read = |path: &Path| Motion::from_bvh(&bvh::read_path(path, ReadOptions::default()).unwrap());
    let (src, out) = (read(&source), read(&back));
    assert_eq!(src.frames(), frames, "the source is at the model's frame rate");
    let tolerance = 1e-3 * src.skeleton().diameter();
    for &f in &anchored {
        let (a, b) = (src.translations(f)[0], out.translations(f)[0]);
        assert!((a.x - b.x).hypot(a.z - b.z) < tolerance, "frame {f}: root at {b} against {a}");
    }
    let moved = dir.join("walk.horse.bvh");
    let transfer = with(
        vec![
            "transfer".into(),
            source.to_string_lossy().into(),
            "--to".into(),
            horse.to_string_lossy().into(),
            "-o".into(),
            moved.to_string_lossy().into(),
        ],
        &model,
    );
    ok(anymo(&models, &strs(&transfer)).output().unwrap());
    assert_eq!(hierarchy(&moved), hierarchy(&horse));

    // Tokens that do not fit the checkpoint are refused with a reason, and so are anchors
    // outside the clip.
    let written = std::fs::read_to_string(&tokens).unwrap();
    let last = format!("\"frame\":{}", frames - 1);
    assert!(written.contains(&last), "the last anchor is written as {last}");
    std::fs::write(&tokens, written.replacen(&last, &format!("\"frame\":{frames}"), 1)).unwrap();
    let refused = anymo(&models, &strs(&detok)).output().unwrap();
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("root anchors must lie inside the clip"));
    std::fs::write(&tokens, written.replacen("[[[", "[[[99999,", 1)).unwrap();
    let refused = anymo(&models, &strs(&detok)).output().unwrap();
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("do not fit checkpoint"));
}

//! Search on real clips through the `anymo` binary: ingest indexes a small library (gallops,
//! walks and other actions of horses, donkeys, dogs and other quadrupeds, and a few people),
//! then text, filters, example clips, pages and refusals are checked against concrete expected
//! hits; a second ingest adds clips to the index in place; the retrieval eval runs on a sample.

use anymo_tests::{data_dir, manifest, models_dir, scratch_dir, succeeded};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};

fn anymo(data: &Path, models: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_anymo"))
        .args(args)
        .arg("--data-dir")
        .arg(data)
        .env("ANYMO_MODELS", models)
        .env_remove("DATABASE_URL")
        .output()
        .expect("anymo runs")
}

fn search(data: &Path, models: &Path, args: &[&str]) -> Vec<Value> {
    let mut all = vec!["search", "--json"];
    all.extend_from_slice(args);
    let out = succeeded(anymo(data, models, &all));
    let page: Value = serde_json::from_slice(&out.stdout).expect("JSON output");
    page["hits"].as_array().expect("a hits list").clone()
}

fn paths(hits: &[Value]) -> Vec<String> {
    hits.iter().map(|h| h["path"].as_str().unwrap().rsplit('/').next().unwrap().to_string()).collect()
}

#[test]
fn search_by_text_filters_and_example() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let scratch = scratch_dir("search");
    let data = scratch.join("data");
    let wanted = |p: &str| {
        p.contains("Gallop")
            || p.contains("/Horse__")
            || p.contains("/Donkey__")
            || p.contains("Husky__Walk")
            || p.contains("dataset-1_walk_normal")
            || p.contains("dataset-1_bow_angry")
    };
    let first = manifest(&shared, &scratch, &|p| wanted(p) && !p.contains("Wolf"));
    let out = succeeded(anymo(&data, &models, &["ingest", first.to_str().unwrap()]));
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(report.contains("search index: 48 clips indexed, 0 removed"), "{report}");

    // Text: horse gallops first (the white horse is another rig), then donkey or horse jumps.
    let hits = search(&data, &models, &["a horse gallops", "-k", "4"]);
    assert_eq!(paths(&hits[..2]), ["Horse__Gallop.bvh.gz", "Horse_White__Gallop.bvh.gz"]);
    assert!(hits[0]["caption"].as_str().unwrap().contains("gallops"));
    let marked: Vec<[usize; 2]> = serde_json::from_value(hits[0]["highlights"].clone()).unwrap();
    let caption = hits[0]["caption"].as_str().unwrap();
    let words: Vec<&str> = marked.iter().map(|[a, b]| &caption[*a..*b]).collect();
    assert_eq!(words, ["horse", "gallops"]);
    assert_eq!(hits[0]["ranks"]["bm25"], 1);

    // A description in other words still finds gallops of quadrupeds first, the jumping ones on
    // top ("quadruped" is in no caption, so BM25's word matches count for less than the
    // sentence embedding's).
    let hits = paths(&search(&data, &models, &["a quadruped gallops then jumps", "-k", "5"]));
    assert!(hits.iter().all(|p| p.contains("Gallop")), "{hits:?}");
    assert!(hits[..3].iter().all(|p| p.contains("Gallop_Jump")), "{hits:?}");

    // Filters: subject words, licence, source prefix and duration.
    let dogs = search(&data, &models, &["gallop", "--subject", "dog", "--licence", "cc0-1.0", "-k", "10"]);
    // The library's five dog clips (two rigs), their plain gallops first.
    assert_eq!(dogs.len(), 5, "{:?}", paths(&dogs));
    let mut first_two = paths(&dogs[..2]);
    first_two.sort();
    assert_eq!(first_two, ["Husky__Gallop.bvh.gz", "ShibaInu__Gallop.bvh.gz"]);
    assert!(dogs.iter().all(|h| h["licence"] == "CC0-1.0"));
    assert!(dogs.iter().all(|h| h["subject"].as_str().unwrap().ends_with("dog")));
    let people = search(&data, &models, &["walk", "--source", "bandai", "-k", "10"]);
    assert!(!people.is_empty() && people.iter().all(|h| h["source"].as_str().unwrap().starts_with("bandai")));
    let short = search(&data, &models, &["gallop", "--max-seconds", "0.6", "-k", "50"]);
    assert!(!short.is_empty() && short.iter().all(|h| h["seconds"].as_f64().unwrap() <= 0.6));

    // Pages continue where the last one stopped.
    let ten = search(&data, &models, &["a horse gallops", "-k", "10"]);
    let second = search(&data, &models, &["a horse gallops", "-k", "5", "--offset", "5"]);
    assert_eq!(paths(&second), paths(&ten[5..]));

    // By example, across skeletons: a husky's gallop finds the shiba inu's gallop among dogs.
    let like = shared.join("quaternius/bvh/animals_pack/Husky__Gallop.bvh.gz");
    let hits = search(&data, &models, &["--like", like.to_str().unwrap(), "--subject", "shiba", "-k", "3"]);
    assert_eq!(paths(&hits)[0], "ShibaInu__Gallop.bvh.gz");
    let hits = search(&data, &models, &["--like", like.to_str().unwrap(), "-k", "1"]);
    assert_eq!(paths(&hits), ["Husky__Gallop.bvh.gz"]);

    // Refusals say what is wrong.
    let refused = |args: &[&str], message: &str| {
        let out = anymo(&data, &models, args);
        assert!(!out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(message), "{stderr}");
    };
    refused(&["search"], "give words to search for, --like CLIP, or both");
    refused(&["search", "walk", "-k", "0"], "the page size must be between 1 and 100; 0 was asked");
    refused(
        &["search", "walk", "--min-seconds", "3", "--max-seconds", "2"],
        "the shortest duration (3 s) is longer than the longest (2 s)",
    );

    // A second ingest indexes only the new clips, in place; searching indexes nothing more.
    let second = manifest(&shared, &scratch, &wanted);
    let out = succeeded(anymo(&data, &models, &["ingest", second.to_str().unwrap()]));
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(report.contains("search index: 2 clips indexed, 0 removed"), "{report}");
    assert!(report.contains("50 clips searchable"), "{report}");
    let out = succeeded(anymo(&data, &models, &["search", "a wolf gallops", "-k", "1"]));
    assert!(String::from_utf8_lossy(&out.stdout).contains("Wolf__Gallop.bvh.gz"));
    assert!(!String::from_utf8_lossy(&out.stderr).contains("index updated"));
}

#[test]
fn retrieval_eval_on_a_sample_calibrates_and_measures_paraphrases() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let scratch = scratch_dir("search-eval");
    let json = scratch.join("retrieval.json");
    let manifest = shared.join("manifest.tsv");
    let out = succeeded(anymo(
        &scratch,
        &models,
        &[
            "eval",
            "retrieval",
            "--manifest",
            manifest.to_str().unwrap(),
            "--limit",
            "40",
            "--calibrate",
            "--json",
            json.to_str().unwrap(),
        ],
    ));
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("| caption -> motion | hybrid |"), "{table}");
    assert!(table.contains("| paraphrase -> motion | hybrid |"), "{table}");
    assert_eq!(table.matches("| chosen |").count(), 1, "{table}");
    let report: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let report = &report["report"];
    assert_eq!(report["calibration"]["chosen"], report["hybrid"]);
    let rows = report["rows"].as_array().unwrap();
    let summary = |task: &str, retrievers: &str, subset: &str| {
        let row = rows
            .iter()
            .find(|r| r["task"] == task && r["retrievers"] == retrievers && r["subset"] == subset)
            .unwrap_or_else(|| panic!("no {task} / {retrievers} / {subset} row"));
        row["summary"].clone()
    };
    let hybrid = summary("caption -> motion", "hybrid", "all");
    assert!(hybrid["queries"].as_u64().unwrap() > 0);
    let (r1, r5, r10) =
        (hybrid["r1"].as_f64().unwrap(), hybrid["r5"].as_f64().unwrap(), hybrid["r10"].as_f64().unwrap());
    assert!(r1 <= r5 && r5 <= r10 && r10 <= 1.0);
    // Far better than chance (1/queries at R@1) on held-out captions.
    assert!(r5 > 0.5, "hybrid R@5 {r5}");
    // Paraphrases share no words with their answers: BM25 alone barely finds them, and the
    // calibrated fusion must not let its incidental matches win.
    let development = |retrievers: &str| summary("paraphrase -> motion", retrievers, "development half");
    let (bm25, fused) = (development("BM25")["mrr"].as_f64().unwrap(), development("hybrid")["mrr"].as_f64().unwrap());
    assert!(development("hybrid")["queries"].as_u64().unwrap() >= 10);
    assert!(fused > 2.0 * bm25, "paraphrase MRR: hybrid {fused}, BM25 {bm25}");
}

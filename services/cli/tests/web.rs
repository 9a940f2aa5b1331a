//! The web page, served by `anymo serve` on a small real library: its files come from the binary
//! (gzip, ETags, a content security policy, nothing from elsewhere), and in headless Chromium
//! (`tests/e2e/page.mjs`, with playwright-core) a user generates on an uploaded skeleton and
//! sees it play, meets an API error in place, searches with and without a filter, previews, opens a clip, finds similar
//! clips and transfers one. Screenshots are kept in `target/e2e-screenshots`.

mod common;

use anymo_tests::{data_dir, gunzip, models_dir, scratch_dir, test_tool};
use common::{ingested_library, serve};
use serde_json::Value;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A GET's status, headers and body (undecoded: this client asks for no compression itself).
struct Fetched {
    status: u16,
    headers: reqwest::header::HeaderMap,
    body: Vec<u8>,
}

impl Fetched {
    fn header(&self, name: &str) -> &str {
        self.headers.get(name).map_or("", |v| v.to_str().unwrap())
    }

    fn json(&self) -> Value {
        serde_json::from_slice(&self.body).expect("a JSON body")
    }
}

fn get(url: &str, headers: &[(&str, &str)]) -> Fetched {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    runtime.block_on(async {
        let mut request = reqwest::Client::new().get(url);
        for (k, v) in headers {
            request = request.header(*k, *v);
        }
        let response = request.send().await.expect("an answer");
        let (status, headers) = (response.status().as_u16(), response.headers().clone());
        Fetched { status, headers, body: response.bytes().await.expect("a body").to_vec() }
    })
}

/// The page's files as a browser fetches them, and the facts the page asks the API for.
fn files_are_served_from_the_binary(base: &str) {
    let page = get(&format!("{base}/"), &[]);
    assert_eq!(page.status, 200);
    assert_eq!(page.header("content-type"), "text/html; charset=utf-8");
    assert!(page.header("content-security-policy").starts_with("default-src 'self'"));
    let html = String::from_utf8(page.body.clone()).unwrap();
    assert!(html.contains(r#"<script type="module" src="/ui/app.js">"#), "{html}");
    assert!(!html.contains("http://") && !html.contains("https://"), "the page loads nothing from elsewhere");

    let again = get(&format!("{base}/"), &[("if-none-match", page.header("etag"))]);
    assert_eq!(again.status, 304, "an unchanged page is not sent again");

    let plain = get(&format!("{base}/ui/vendor/three.module.js"), &[]).body;
    let zipped = get(&format!("{base}/ui/vendor/three.module.js"), &[("accept-encoding", "gzip, br")]);
    assert_eq!(zipped.header("content-encoding"), "gzip");
    assert_eq!(zipped.header("content-type"), "text/javascript; charset=utf-8");
    assert!(
        zipped.body.len() * 3 < plain.len(),
        "three.js goes compressed: {} of {} bytes",
        zipped.body.len(),
        plain.len()
    );
    let mut unzipped = Vec::new();
    flate2::read::GzDecoder::new(zipped.body.as_slice()).read_to_end(&mut unzipped).unwrap();
    assert_eq!(unzipped, plain);
    let loader = String::from_utf8(get(&format!("{base}/ui/vendor/BVHLoader.js"), &[]).body).unwrap();
    assert!(loader.contains("from './three.module.js';") && !loader.contains("from 'three'"));

    let missing = get(&format!("{base}/ui/no-such-file.js"), &[]);
    assert_eq!(missing.status, 404);
    assert_eq!(missing.json()["error"]["code"], "not_found");

    let health = get(&format!("{base}/v1/health"), &[]).json();
    assert_eq!(health["limits"]["samples"], 8, "{health}");
    assert_eq!(health["limits"]["seconds"], 30.0, "{health}");
    let skeletons = get(&format!("{base}/v1/skeletons"), &[]).json();
    let kinds: Vec<String> =
        skeletons.as_array().unwrap().iter().map(|s| format!("{} {}", s["subjects"], s["sources"])).collect();
    assert!(kinds.iter().any(|k| k.starts_with(r#"["horse"]"#)), "{kinds:?}");
    assert!(kinds.iter().any(|k| k.starts_with(r#"["person"]"#) && k.contains("bandai")), "{kinds:?}");
}

#[test]
fn the_page_generates_plays_searches_and_transfers() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let scratch = scratch_dir("web");
    let data = ingested_library(&shared, &models, &scratch);
    let server = serve(&data, &models, &[], &[]);
    files_are_served_from_the_binary(&server.base);

    let e2e = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/e2e");
    let chromium = std::env::var_os("ANYMO_CHROMIUM").map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from);
    if !test_tool(&e2e.join("node_modules/playwright-core/package.json"), "playwright-core")
        || !test_tool(&chromium, "Chromium")
    {
        return;
    }
    let husky = scratch.join("husky.bvh");
    gunzip(&shared.join("quaternius/bvh/animals_pack/Husky__Walk.bvh.gz"), &husky);
    let broken = scratch.join("broken.bvh");
    std::fs::write(&broken, "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n}\n")
        .unwrap();
    let screenshots = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/e2e-screenshots");
    let out = Command::new("node")
        .arg(e2e.join("page.mjs"))
        .args(["--base", &server.base, "--query", "a horse gallops"])
        .arg("--out")
        .arg(&screenshots)
        .arg("--skeleton")
        .arg(&husky)
        .arg("--broken")
        .arg(&broken)
        .env("ANYMO_CHROMIUM", &chromium)
        .output()
        .expect("node runs (Node.js is needed for the browser test)");
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}\n{said}", String::from_utf8_lossy(&out.stderr));
    let report: Value = serde_json::from_str(said.lines().last().expect("a report")).expect("a JSON report");
    eprintln!("web page: {report}");
    assert!(report["error"].as_str().unwrap().contains("line 4"), "{report}");
    assert!(report["firstHit"].as_str().unwrap().contains("horse"), "{report}");
    assert!(report["similar"].as_u64().unwrap() > 0 && report["joints"].as_u64().unwrap() >= 20, "{report}");
    // The page shows each sample's quality report, and it says the dog is plausible: feet found
    // and on the floor (no higher than twice real husky clips'), no jumps, its body carried at
    // the height real clips carry it, shaking within three times real clips'.
    let quality = &report["generateQuality"];
    let real = &quality["real"];
    assert!(quality["feet"].as_u64().unwrap() >= 2 && quality["max_step"].as_f64().unwrap() < 0.1, "{report}");
    assert!(quality["foot_flight"].as_f64().unwrap() < 2.0 * real["foot_flight"].as_f64().unwrap(), "{report}");
    let height = quality["body_height"].as_f64().unwrap() / real["body_height"].as_f64().unwrap();
    assert!((height - 1.0).abs() < 0.35, "{report}");
    assert!(quality["jitter_ratio"].as_f64().unwrap() < 3.0, "{report}");
    assert!(quality["text_similarity"].as_f64().is_some_and(|t| (-1.0..=1.0).contains(&t)), "{report}");
    for shot in ["generate.png", "library.png", "transfer.png", "generate-sample-1.png", "generate-sample-2.png"] {
        let bytes = std::fs::read(screenshots.join(shot)).unwrap_or_else(|e| panic!("{shot}: {e}"));
        assert!(bytes.starts_with(b"\x89PNG"), "{shot} is a PNG");
    }
}

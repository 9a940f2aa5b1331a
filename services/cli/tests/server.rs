//! The server end to end, through the `anymo serve` binary on a small real library (horses,
//! huskies and a few people) with the shipped checkpoints: every REST capability with its
//! refusals, gRPC with reflection, keys, the queue's back-pressure, upload ingest as a job,
//! graceful shutdown with a request in flight, a SIGKILL during an upload ingest, and two
//! replicas on one PostgreSQL.

mod common;

use anymo_motion::bvh;
use anymo_tests::{data_dir, models_dir, scratch_dir, succeeded, test_tool};
use common::{KEY, anymo, ingested_library, serve};
use reqwest::multipart::{Form, Part};
use serde_json::Value;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap()
}

fn clip_text(path: &Path) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    let mut text = Vec::new();
    flate2::read::MultiGzDecoder::new(bytes.as_slice()).read_to_end(&mut text).unwrap();
    text
}

fn file(bytes: Vec<u8>, name: &str) -> Part {
    Part::bytes(bytes).file_name(name.to_string())
}

fn joint_names(text: &[u8]) -> Vec<String> {
    let clip = bvh::read(text, bvh::ReadOptions::default()).expect("valid BVH");
    clip.skeleton().joints().iter().map(|j| j.name.clone()).collect()
}

fn frames(text: &[u8]) -> usize {
    bvh::read(text, bvh::ReadOptions::default()).expect("valid BVH").frames()
}

/// Asserts a JSON error: its status and code, and that its message says `says`.
async fn refused(response: reqwest::Response, status: u16, code: &str, says: &str) {
    assert_eq!(response.status().as_u16(), status, "expected {status} {code}");
    let body: Value = response.json().await.expect("a JSON error");
    assert_eq!(body["error"]["code"], code, "{body}");
    let message = body["error"]["message"].as_str().unwrap();
    assert!(message.contains(says), "{message:?} should say {says:?}");
}

/// The JSON answer of a GET.
async fn get_json(client: &reqwest::Client, url: impl reqwest::IntoUrl) -> Value {
    client.get(url).send().await.expect("an answer").json().await.expect("a JSON answer")
}

async fn wait_for_job(client: &reqwest::Client, base: &str, id: i64) -> Value {
    let started = Instant::now();
    loop {
        let job: Value = get_json(client, format!("{base}/v1/jobs/{id}")).await;
        if job["status"] == "done" || job["status"] == "failed" {
            return job;
        }
        assert!(started.elapsed() < Duration::from_secs(300), "job {id} did not finish: {job}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// How much higher than real clips of its rig the lowest foot may be on average (the issue's
/// bound for walks: twice real).
const FLOATING: f64 = 2.0;

/// How much more a generated walk may shake than real clips of its rig, in these tests.
const JITTER_RATIO: f64 = 3.0;

/// How far the body's mean height may stray from real clips of its rig (a dog on its hind legs
/// carries its body about twice as high).
const POSTURE: f64 = 0.35;

/// Checks that a generated animal's quality report says it is plausible for its rig (whose
/// clips in the corpus include `subject`): feet found and planted on the floor, no jumps, its
/// body carried at the height real clips carry it, and, for a walk, shaking within a factor of
/// the real clips' median (a gallop is more lively than most clips of its rig).
fn plausible(quality: &Value, subject: &str, walk: bool) {
    let real = &quality["real"];
    assert!(real["subject"].as_str().unwrap().split(", ").any(|s| s == subject), "{quality}");
    assert!(quality["feet"].as_u64().unwrap() >= 2 && quality["cleaned_up"].as_bool().unwrap(), "{quality}");
    assert!(quality["planted"].as_f64().unwrap() > 0.2, "{quality}");
    let flight = quality["foot_flight"].as_f64().unwrap() / real["foot_flight"].as_f64().unwrap();
    assert!(flight < FLOATING, "the feet float {flight} times as high as real clips' ({quality})");
    assert!(quality["max_step"].as_f64().unwrap() < 0.1, "{quality}");
    let height = quality["body_height"].as_f64().unwrap() / real["body_height"].as_f64().unwrap();
    assert!((height - 1.0).abs() < POSTURE, "the body is carried at {height} times the real clips' height ({quality})");
    let ratio = quality["jitter_ratio"].as_f64().unwrap();
    assert!(!walk || ratio < JITTER_RATIO, "jitter {ratio} times the real clips' ({quality})");
    let text = quality["text_similarity"].as_f64().unwrap();
    assert!((-1.0..=1.0).contains(&text), "{quality}");
}

#[test]
fn rest_and_grpc_serve_every_capability() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let scratch = scratch_dir("server");
    let data = ingested_library(&shared, &models, &scratch);
    // Two search models' threads on any machine, so that queries sent at once (below) are
    // shared between them.
    let server = serve(&data, &models, &["--max-body-bytes", "300000", "--search-workers", "2"], &[]);
    let base = server.base.clone();
    let husky_path = shared.join("quaternius/bvh/animals_pack/Husky__Walk.bvh.gz");
    let husky = clip_text(&husky_path);
    let husky_joints = joint_names(&husky);
    runtime().block_on(async {
        let client = reqwest::Client::new();
        let health: Value = get_json(&client, format!("{base}/v1/health")).await;
        let clips = health["clips"].as_i64().unwrap();
        assert!(clips > 20, "{health}");
        assert_eq!(client.get(format!("{base}/v1/ready")).send().await.unwrap().status(), 200);

        // The OpenAPI document names every endpoint, and the docs page is served.
        let api: Value = get_json(&client, format!("{base}/openapi.json")).await;
        assert!(api["openapi"].as_str().unwrap().starts_with("3."));
        for path in ["/v1/generate", "/v1/edit/inpaint", "/v1/transfer", "/v1/tokenize", "/v1/search", "/v1/ingest"] {
            assert!(api["paths"][path].is_object(), "{path} is documented");
        }
        let docs = client.get(format!("{base}/docs/")).send().await.unwrap();
        assert_eq!(docs.status(), 200);
        assert!(docs.text().await.unwrap().contains("swagger"), "the docs page is Swagger UI");

        // Generate on an uploaded skeleton: BVH text on that skeleton, exactly 2 s long.
        let form = Form::new()
            .text("prompt", "a dog walks")
            .text("seconds", "2")
            .part("skeleton", file(husky.clone(), "husky.bvh"));
        let response = client.post(format!("{base}/v1/generate")).multipart(form).send().await.unwrap();
        assert_eq!(response.status(), 200);
        let id: i64 = response.headers()["x-generation-id"].to_str().unwrap().parse().unwrap();
        let quality: Value = serde_json::from_str(response.headers()["x-quality"].to_str().unwrap()).unwrap();
        let bvh_text = response.bytes().await.unwrap().to_vec();
        assert_eq!(joint_names(&bvh_text), husky_joints);
        assert_eq!(frames(&bvh_text), 60);
        plausible(&quality, "husky dog", true);
        // The result is stored and fetched again byte for byte, with its quality report.
        let again = client.get(format!("{base}/v1/generations/{id}/samples/0")).send().await.unwrap();
        assert_eq!(again.bytes().await.unwrap().to_vec(), bvh_text);
        let record: Value = get_json(&client, format!("{base}/v1/generations/{id}")).await;
        assert_eq!(record["request"]["prompt"], "a dog walks");
        assert_eq!(record["quality"], serde_json::json!([quality]));

        // JSON: every sample with its BVH; sample 0 of seed 0 is the motion above.
        let form = Form::new()
            .text("prompt", "a dog walks")
            .text("seconds", "2")
            .text("samples", "2")
            .part("skeleton", file(husky.clone(), "husky.bvh"));
        let samples: Value = client
            .post(format!("{base}/v1/generate"))
            .header("accept", "application/json")
            .multipart(form)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        let samples = samples.as_array().unwrap();
        assert_eq!(samples.len(), 2);
        assert_eq!(samples[0]["bvh"].as_str().unwrap().as_bytes(), bvh_text.as_slice());
        assert_ne!(samples[0]["bvh"], samples[1]["bvh"]);
        assert_eq!(samples[0]["quality"], quality, "the same motion has the same report");
        plausible(&samples[1]["quality"], "husky dog", true);

        // JSON with a stored skeleton.
        let skeletons: Value = get_json(&client, format!("{base}/v1/skeletons")).await;
        let horse = skeletons.as_array().unwrap().iter().find(|s| s["joints"] == 51).expect("the horse rig");
        let horse_id = horse["id"].as_i64().unwrap();
        let horse_bvh =
            client.get(format!("{base}/v1/skeletons/{horse_id}/bvh")).send().await.unwrap().bytes().await.unwrap();
        let body =
            serde_json::json!({ "prompt": "a horse gallops", "seconds": 1, "skeleton_id": horse_id, "score": false });
        let response = client.post(format!("{base}/v1/generate")).json(&body).send().await.unwrap();
        let quality: Value = serde_json::from_str(response.headers()["x-quality"].to_str().unwrap()).unwrap();
        assert!(quality["text_similarity"].is_null() && quality["jitter"].as_f64().is_some(), "score=false: {quality}");
        let body =
            serde_json::json!({ "prompt": "a horse gallops", "seconds": 1.5, "skeleton_id": horse_id, "seed": 3 });
        let response = client.post(format!("{base}/v1/generate")).json(&body).send().await.unwrap();
        assert_eq!(response.status(), 200);
        let quality: Value = serde_json::from_str(response.headers()["x-quality"].to_str().unwrap()).unwrap();
        let text = response.bytes().await.unwrap();
        assert_eq!(joint_names(&text), joint_names(&horse_bvh));
        assert_eq!(frames(&text), 45);
        plausible(&quality, "horse", false);

        // Refusals are JSON with a code and say what to change.
        let generate = |form: Form| client.post(format!("{base}/v1/generate")).multipart(form).send();
        let mut broken = husky.clone();
        broken.splice(0..9, b"HIERARCHX".iter().copied());
        let form =
            Form::new().text("prompt", "a dog walks").text("seconds", "2").part("skeleton", file(broken, "bad.bvh"));
        refused(generate(form).await.unwrap(), 400, "bad_bvh", "line 1, column 1").await;
        let form = Form::new()
            .text("prompt", "a dog walks")
            .text("seconds", "31")
            .part("skeleton", file(husky.clone(), "h.bvh"));
        refused(generate(form).await.unwrap(), 422, "over_limit", "limited to 30 s").await;
        let form = Form::new()
            .text("prompt", "a dog walks")
            .text("samples", "9")
            .part("skeleton", file(husky.clone(), "h.bvh"));
        refused(generate(form).await.unwrap(), 422, "over_limit", "limited to 8").await;
        let form = Form::new().text("prompt", "  ").part("skeleton", file(husky.clone(), "h.bvh"));
        refused(generate(form).await.unwrap(), 400, "bad_request", "prompt is empty").await;
        refused(generate(Form::new().text("prompt", "a dog walks")).await.unwrap(), 400, "bad_request", "skeleton")
            .await;
        let body = serde_json::json!({ "prompt": "walks", "skeleton_id": 999_999 });
        refused(
            client.post(format!("{base}/v1/generate")).json(&body).send().await.unwrap(),
            404,
            "not_found",
            "999999",
        )
        .await;
        let plain = client.post(format!("{base}/v1/generate")).body("prompt=walk").send().await.unwrap();
        refused(plain, 400, "bad_request", "multipart/form-data or application/json").await;
        // A body over the limit, from a client of its own: the server answers before reading it
        // all and closes that connection.
        let big = Form::new().text("prompt", "walks").part("skeleton", file(vec![b' '; 400_000], "big.bvh"));
        let alone = reqwest::Client::new().post(format!("{base}/v1/generate")).multipart(big).send();
        refused(alone.await.unwrap(), 413, "too_large", "300000 bytes").await;
        refused(client.get(format!("{base}/v1/clips/abc")).send().await.unwrap(), 404, "not_found", "").await;
        refused(client.get(format!("{base}/v1/nothing")).send().await.unwrap(), 404, "not_found", "/openapi.json")
            .await;

        // The corpus: pages of clips, a clip's record and its exact bytes.
        let page: Value = get_json(&client, format!("{base}/v1/clips?limit=500")).await;
        let page = page.as_array().unwrap();
        assert_eq!(page.len() as i64, clips);
        let walk = page.iter().find(|c| c["path"].as_str().unwrap().ends_with("Husky__Walk.bvh.gz")).unwrap();
        let walk_id = walk["id"].as_i64().unwrap();
        let stored = client.get(format!("{base}/v1/clips/{walk_id}/bvh")).send().await.unwrap().bytes().await.unwrap();
        assert!(stored.to_vec() == husky, "a clip downloads exactly as ingested");
        let next: Value = get_json(&client, format!("{base}/v1/clips?after={}&limit=2", page[0]["id"])).await;
        assert_eq!(next[0]["id"], page[1]["id"]);

        // Edit: continuing the husky's walk by 1 s adds 30 frames at 30 fps.
        let form = Form::new().text("prompt", "a dog walks").text("seconds", "1").text("clip_id", walk_id.to_string());
        let response = client.post(format!("{base}/v1/edit/continue")).multipart(form).send().await.unwrap();
        assert_eq!(response.status(), 200);
        let continued = response.bytes().await.unwrap();
        assert_eq!(frames(&continued), frames(&husky) + 30);
        let form = Form::new()
            .text("prompt", "a dog walks")
            .text("from", "0.2")
            .text("to", "0.4")
            .part("clip", file(husky.clone(), "w.bvh"));
        let response = client.post(format!("{base}/v1/edit/inpaint")).multipart(form).send().await.unwrap();
        assert_eq!(response.status(), 200);
        assert_eq!(frames(&response.bytes().await.unwrap()), frames(&husky));

        // Transfer a stored horse clip onto the uploaded husky skeleton.
        let horse_clip = page.iter().find(|c| c["path"].as_str().unwrap().ends_with("Horse__Gallop.bvh.gz")).unwrap();
        let form =
            Form::new().text("clip_id", horse_clip["id"].to_string()).part("skeleton", file(husky.clone(), "h.bvh"));
        let response = client.post(format!("{base}/v1/transfer")).multipart(form).send().await.unwrap();
        assert_eq!(response.status(), 200);
        let quality: Value = serde_json::from_str(response.headers()["x-quality"].to_str().unwrap()).unwrap();
        assert_eq!(joint_names(&response.bytes().await.unwrap()), husky_joints);
        assert_eq!((quality["cleaned_up"].as_bool(), quality["text_similarity"].as_f64()), (Some(true), None));
        // The cleanup can be turned off.
        let form = Form::new()
            .text("clip_id", horse_clip["id"].to_string())
            .text("cleanup", "false")
            .part("skeleton", file(husky.clone(), "h.bvh"));
        let response = client.post(format!("{base}/v1/transfer")).multipart(form).send().await.unwrap();
        let quality: Value = serde_json::from_str(response.headers()["x-quality"].to_str().unwrap()).unwrap();
        assert_eq!((quality["cleaned_up"].as_bool(), quality["planted"].as_f64()), (Some(false), Some(0.0)));
        let form =
            Form::new().text("clip_id", "1").text("cleanup", "maybe").part("skeleton", file(husky.clone(), "h.bvh"));
        let response = client.post(format!("{base}/v1/transfer")).multipart(form).send().await.unwrap();
        refused(response, 400, "bad_request", "cleanup must be true or false").await;

        // Tokens: tokenize a clip, decode the tokens onto the horse.
        let body = serde_json::json!({ "clip_id": walk_id });
        let tokens: Value =
            client.post(format!("{base}/v1/tokenize")).json(&body).send().await.unwrap().json().await.unwrap();
        assert_eq!(tokens["model"], "tat-v2");
        assert_eq!(tokens["tokens"]["frames"].as_u64().unwrap() as usize, frames(&husky));
        let body = serde_json::json!({ "tokens": tokens, "skeleton_id": horse_id });
        let response = client.post(format!("{base}/v1/detokenize")).json(&body).send().await.unwrap();
        assert_eq!(response.status(), 200);
        assert_eq!(joint_names(&response.bytes().await.unwrap()), joint_names(&horse_bvh));
        let mut bad = tokens.clone();
        bad["tokens"]["codes"][0][0][0] = 5000.into();
        let body = serde_json::json!({ "tokens": bad, "skeleton_id": horse_id });
        refused(
            client.post(format!("{base}/v1/detokenize")).json(&body).send().await.unwrap(),
            422,
            "refused",
            "do not fit",
        )
        .await;

        // Search: by text with a filter, by stored example, by uploaded example.
        let page: Value = get_json(&client, format!("{base}/v1/search?q=a%20horse%20gallops&limit=3")).await;
        assert!(page["hits"][0]["path"].as_str().unwrap().ends_with("Horse__Gallop.bvh.gz"), "{page}");
        let page: Value = get_json(&client, format!("{base}/v1/search?q=gallop&subject=dog&limit=10")).await;
        let hits = page["hits"].as_array().unwrap();
        assert!(!hits.is_empty() && hits.iter().all(|h| h["subject"] == "husky dog"), "{page}");
        let page: Value = get_json(&client, format!("{base}/v1/search?like_clip={walk_id}&limit=1")).await;
        assert_eq!(page["hits"][0]["id"].as_i64().unwrap(), walk_id);
        let form = Form::new().part("like", file(husky.clone(), "w.bvh")).text("limit", "1");
        let page: Value =
            client.post(format!("{base}/v1/search")).multipart(form).send().await.unwrap().json().await.unwrap();
        assert_eq!(page["hits"][0]["id"].as_i64().unwrap(), walk_id);
        refused(client.get(format!("{base}/v1/search")).send().await.unwrap(), 400, "bad_request", "give words").await;
        refused(
            client.get(format!("{base}/v1/search?q=walk&limit=101")).send().await.unwrap(),
            400,
            "bad_request",
            "100",
        )
        .await;

        // Ingest needs a key; a malformed upload is refused whole, naming the file and line.
        let upload = || {
            Form::new()
                .part("files", file(husky.clone(), "my_husky.bvh"))
                .text("licence", "CC0-1.0")
                .text("subject", "husky dog")
        };
        let response = client.post(format!("{base}/v1/ingest")).multipart(upload()).send().await.unwrap();
        refused(response, 401, "unauthorized", "API key").await;
        // A keyless upload near the body limit gets its refusal, not a connection closed while
        // it is still being sent.
        for _ in 0..5 {
            let big = upload().part("files", file(vec![b' '; 200_000], "padding.bvh"));
            let response = client.post(format!("{base}/v1/ingest")).multipart(big).send().await.unwrap();
            refused(response, 401, "unauthorized", "API key").await;
        }
        let bad = upload().part("files", file(b"HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n".to_vec(), "broken.bvh"));
        let response = client.post(format!("{base}/v1/ingest")).bearer_auth(KEY).multipart(bad).send().await.unwrap();
        refused(response, 400, "bad_bvh", "\"broken.bvh\" is not a valid BVH file: line ").await;
        // The husky walk is stored already; a second copy under a new name is "already stored".
        let mut changed = husky.clone();
        changed.extend_from_slice(b"\n");
        let form = upload()
            .part("files", file(changed, "another.bvh"))
            .part("files", file(b"a husky prances proudly\n".to_vec(), "another.txt"));
        let response =
            client.post(format!("{base}/v1/ingest")).header("x-api-key", KEY).multipart(form).send().await.unwrap();
        assert_eq!(response.status(), 202);
        let job: Value = response.json().await.unwrap();
        let job = wait_for_job(&client, &base, job["id"].as_i64().unwrap()).await;
        assert_eq!(job["status"], "done", "{job}");
        assert_eq!(
            (job["result"]["added"].as_i64(), job["result"]["already_stored"].as_i64()),
            (Some(1), Some(1)),
            "{job}"
        );
        let page: Value = get_json(&client, format!("{base}/v1/search?q=prances&limit=5")).await;
        let found = &page["hits"][0];
        assert!(found["path"].as_str().unwrap().ends_with("another.bvh"), "{page}");
        assert_eq!(found["licence"], "CC0-1.0");
        let new_id = found["id"].as_i64().unwrap();

        // Delete needs the key too.
        let url = format!("{base}/v1/clips/{new_id}");
        refused(client.delete(&url).send().await.unwrap(), 401, "unauthorized", "API key").await;
        refused(client.delete(&url).bearer_auth("wrong").send().await.unwrap(), 401, "unauthorized", "not valid").await;
        assert_eq!(client.delete(&url).bearer_auth(KEY).send().await.unwrap().status(), 204);
        refused(client.get(&url).send().await.unwrap(), 404, "not_found", "no clip").await;

        // The page that found the deleted clip is not served again: pages are kept by the
        // store's clips as well as by the request.
        let page: Value = get_json(&client, format!("{base}/v1/search?q=prances&limit=5")).await;
        assert!(page["hits"].as_array().unwrap().iter().all(|h| h["id"] != new_id), "{page}");

        // Queries sent at once are embedded together, and each gets its own answer.
        let embedded = || async {
            let metrics = client.get(format!("{base}/metrics")).send().await.unwrap().text().await.unwrap();
            metric(&metrics, "anymo_search_batch_texts_sum")
        };
        let before = embedded().await;
        let asked = [
            ("a horse jumps while galloping", "horse__gallop_jump"),
            ("a horse kicks with its hind legs", "horse__attack_kick"),
            ("a person bows angrily", "bow_angry"),
            ("a person walks", "walk_normal"),
            ("a husky dog eats", "husky__eating"),
            ("a husky dog dies", "husky__death"),
            ("a horse is hit from the left", "horse__idle_hitreact_left"),
        ];
        let pages = futures_join(
            asked
                .iter()
                .map(|(q, _)| {
                    let (client, url) =
                        (client.clone(), format!("{base}/v1/search?q={}&limit=1", q.replace(' ', "%20")));
                    async move { get_json(&client, url).await }
                })
                .collect(),
        )
        .await;
        for ((q, word), page) in asked.iter().zip(&pages) {
            let hit = &page["hits"][0];
            assert!(hit["path"].as_str().unwrap().to_lowercase().contains(word), "{q:?} found {hit}");
        }
        assert_eq!(embedded().await - before, asked.len() as f64, "each new text embedded once");
        // Asked again, the same queries are answered without embedding anything.
        for (q, _) in &asked {
            get_json(&client, format!("{base}/v1/search?q={}&limit=1", q.replace(' ', "%20"))).await;
        }
        assert_eq!(embedded().await - before, asked.len() as f64, "repeated texts are not embedded again");

        // Metrics count what was answered.
        let metrics = client.get(format!("{base}/metrics")).send().await.unwrap().text().await.unwrap();
        assert!(
            metrics.contains("anymo_http_requests_total{route=\"/v1/generate\",method=\"POST\",status=\"200\"}"),
            "{metrics}"
        );
        assert!(metrics.contains("anymo_motions_generated_total{kind=\"generate\"}"));

        grpc(&base, &husky, &husky_joints).await;
    });
}

/// The same capabilities over gRPC, and reflection.
async fn grpc(base: &str, husky: &[u8], husky_joints: &[String]) {
    use anymo_server::grpc::proto;
    use proto::anymo_client::AnymoClient;
    let mut client = AnymoClient::connect(base.to_string()).await.expect("a gRPC connection");
    let health = client.health(proto::HealthRequest {}).await.unwrap().into_inner();
    assert_eq!(health.status, "ok");
    assert!(health.searchable_clips > 20 && health.clips > 20, "{health:?}");
    let text = String::from_utf8(husky.to_vec()).unwrap();
    let request = proto::GenerateRequest {
        prompt: "a dog walks".into(),
        seconds: Some(2.0),
        skeleton: Some(proto::generate_request::Skeleton::SkeletonBvh(text.clone())),
        sampling: Some(proto::Sampling { samples: Some(1), ..Default::default() }),
    };
    let reply = client.generate(request).await.unwrap().into_inner();
    assert_eq!(reply.frames, 60);
    assert_eq!(joint_names(reply.bvh[0].as_bytes()), husky_joints);
    assert_eq!(reply.quality.len(), 1);
    let quality = &reply.quality[0];
    assert!(quality.cleaned_up && quality.feet >= 2 && quality.text_similarity.is_some(), "{quality:?}");
    assert!(
        quality.real.as_ref().is_some_and(|r| r.subject.contains("husky dog") && r.body_height > 0.0),
        "{quality:?}"
    );
    let search = client
        .search(proto::SearchRequest { text: "a horse gallops".into(), limit: 2, ..Default::default() })
        .await
        .unwrap()
        .into_inner();
    assert!(search.hits[0].path.ends_with("Horse__Gallop.bvh.gz"));
    let refused = client
        .generate(proto::GenerateRequest { prompt: "walks".into(), seconds: Some(40.0), ..Default::default() })
        .await
        .unwrap_err();
    assert_eq!(refused.code(), tonic::Code::InvalidArgument);
    let moved = client
        .transfer(proto::TransferRequest { clip_bvh: text.clone(), target_bvh: text.clone(), cleanup: None })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(joint_names(moved.bvh.as_bytes()), husky_joints);
    assert!(
        moved.quality.is_some_and(|q| q.feet >= 2 && q.text_similarity.is_none()),
        "a transfer's report, without a prompt"
    );

    // Reflection lists the service.
    use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
    use tonic_reflection::pb::v1::server_reflection_request::MessageRequest;
    use tonic_reflection::pb::v1::{ServerReflectionRequest, server_reflection_response::MessageResponse};
    let channel = tonic::transport::Channel::from_shared(base.to_string()).unwrap().connect().await.unwrap();
    let mut reflection = ServerReflectionClient::new(channel);
    let request = ServerReflectionRequest {
        host: String::new(),
        message_request: Some(MessageRequest::ListServices(String::new())),
    };
    let mut answers = reflection.server_reflection_info(tokio_stream::iter([request])).await.unwrap().into_inner();
    let answer = answers.message().await.unwrap().expect("an answer");
    let Some(MessageResponse::ListServicesResponse(list)) = answer.message_response else { panic!("a service list") };
    assert!(list.service.iter().any(|s| s.name == "anymo.v1.Anymo"), "{:?}", list.service);
}

/// Four generations at once against one worker and a queue of one: the excess is answered 429
/// at once, with Retry-After; the rest succeed.
#[test]
fn a_full_queue_answers_429_and_shutdown_finishes_in_flight_work() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let scratch = scratch_dir("server-queue");
    let data = scratch.join("data");
    let mut server = serve(&data, &models, &["--queue", "1", "--workers", "1"], &[]);
    let base = server.base.clone();
    let husky = clip_text(&shared.join("quaternius/bvh/animals_pack/Husky__Walk.bvh.gz"));
    runtime().block_on(async {
        let client = reqwest::Client::new();
        let request = |seconds: &str| {
            let form = Form::new()
                .text("prompt", "a dog walks")
                .text("seconds", seconds.to_string())
                .part("skeleton", file(husky.clone(), "h.bvh"));
            client.post(format!("{base}/v1/generate")).multipart(form).send()
        };
        let answers = futures_join(vec![request("20"), request("20"), request("20"), request("20")]).await;
        let statuses: Vec<u16> = answers.iter().map(|r| r.as_ref().unwrap().status().as_u16()).collect();
        assert!(statuses.contains(&429) && statuses.contains(&200), "{statuses:?}");
        assert!(statuses.iter().all(|s| *s == 200 || *s == 429), "{statuses:?}");
        for response in answers.into_iter().map(Result::unwrap).filter(|r| r.status() == 429) {
            assert_eq!(response.headers()["retry-after"], "1");
            refused(response, 429, "busy", "queue is full").await;
        }

        // SIGTERM with a generation in flight: it is answered, then the server exits cleanly.
        let in_flight = tokio::spawn(request("20"));
        loop {
            let health: Value = get_json(&client, format!("{base}/v1/health")).await;
            if health["generation_running"] == 1 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        let pid = server.child.id().to_string();
        succeeded(Command::new("kill").args(["-TERM", &pid]).output().unwrap());
        let response = in_flight.await.unwrap().unwrap();
        assert_eq!(response.status(), 200);
        assert_eq!(frames(&response.bytes().await.unwrap()), 600);
    });
    let status = server.child.wait().unwrap();
    assert!(status.success(), "the server exits 0 after a graceful shutdown: {status:?}");
}

/// The value of the metric line that starts with `name` in Prometheus' text.
fn metric(metrics: &str, name: &str) -> f64 {
    let line = metrics.lines().find(|l| l.starts_with(name)).unwrap_or_else(|| panic!("no {name} in:\n{metrics}"));
    line.rsplit(' ').next().unwrap().parse().unwrap()
}

/// Awaits every future, keeping their order.
async fn futures_join<F: std::future::Future + Send + 'static>(futures: Vec<F>) -> Vec<F::Output>
where
    F::Output: Send + 'static,
{
    let handles: Vec<_> = futures.into_iter().map(tokio::spawn).collect();
    let mut out = Vec::with_capacity(handles.len());
    for h in handles {
        out.push(h.await.unwrap());
    }
    out
}

/// An upload of every clip of Bandai's dataset 1.
fn upload_form(shared: &Path) -> (Form, Vec<PathBuf>) {
    let files = anymo_tests::files_with_suffix(&shared.join("bandai/dataset-1"), ".bvh.gz");
    let mut form = Form::new().text("licence", "CC-BY-NC-4.0").text("subject", "person");
    for path in &files {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        form = form.part("files", file(std::fs::read(path).unwrap(), &name));
    }
    (form, files)
}

/// The content hashes of a data directory's clips, sorted.
fn content_hashes(data: &Path) -> Vec<String> {
    let store = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap().block_on(async {
        let store = anymo_store::Store::open(&anymo_store::Store::default_url(data)).await.unwrap();
        store.canonical_dump().await.unwrap()
    });
    let mut hashes: Vec<String> = store.iter().map(|line| line.split(' ').nth(1).unwrap().to_string()).collect();
    hashes.sort();
    hashes
}

/// SIGKILL while an upload is being ingested: the clips committed before the kill stay, and
/// the next start resumes the job to the same clips as an uninterrupted ingest.
#[test]
fn sigkill_during_an_upload_ingest_loses_nothing() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let scratch = scratch_dir("server-kill");
    let data = scratch.join("data");
    let (form, files) = upload_form(&shared);
    let count = files.len();
    let mut server = serve(&data, &models, &[], &[]);
    let base = server.base.clone();
    let (job, done_before_kill) = runtime().block_on(async {
        let client = reqwest::Client::new();
        let response = client.post(format!("{base}/v1/ingest")).bearer_auth(KEY).multipart(form).send().await.unwrap();
        assert_eq!(response.status(), 202);
        let job: Value = response.json().await.unwrap();
        let id = job["id"].as_i64().unwrap();
        assert_eq!(job["total"].as_i64().unwrap() as usize, count);
        loop {
            let job: Value = get_json(&client, format!("{base}/v1/jobs/{id}")).await;
            let done = job["done"].as_i64().unwrap();
            if done >= 10 {
                return (id, done as usize);
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    server.child.kill().unwrap();
    server.child.wait().unwrap();
    let stored_after_kill = clip_count(&data, &models);
    assert!(stored_after_kill >= done_before_kill, "{stored_after_kill} stored, {done_before_kill} reported done");
    assert!(stored_after_kill < count, "the kill came before the end ({stored_after_kill} of {count})");

    let server = serve(&data, &models, &[], &[]);
    let base = server.base.clone();
    let job = runtime().block_on(async { wait_for_job(&reqwest::Client::new(), &base, job).await });
    assert_eq!(job["status"], "done", "{job}");
    assert_eq!(job["done"].as_i64().unwrap() as usize, count);
    drop(server);

    // The same files ingested without a kill give the same clips.
    let folder = scratch.join("folder");
    std::fs::create_dir_all(&folder).unwrap();
    for path in &files {
        std::os::unix::fs::symlink(path, folder.join(path.file_name().unwrap())).unwrap();
    }
    let straight = scratch.join("straight");
    succeeded(anymo(&straight, &models, &["ingest", "--no-index", folder.to_str().unwrap()]).output().unwrap());
    assert_eq!(content_hashes(&data), content_hashes(&straight));
    assert_eq!(content_hashes(&data).len(), clip_count(&data, &models));
}

/// Clips in a data directory's store, by `anymo corpus stats`.
fn clip_count(data: &Path, models: &Path) -> usize {
    let out = succeeded(anymo(data, models, &["corpus", "stats"]).output().unwrap());
    let text = String::from_utf8_lossy(&out.stdout);
    text.split_whitespace().next().unwrap().parse().unwrap()
}

/// Two servers on one PostgreSQL: a clip uploaded to one is listed, searchable and usable on
/// the other, and a job accepted by one is visible from both.
#[test]
fn two_replicas_serve_one_postgres_corpus() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let admin =
        std::env::var("ANYMO_TEST_POSTGRES").unwrap_or_else(|_| "postgres://postgres@127.0.0.1:5432/test".into());
    let name = format!("anymo_replicas_{}", std::process::id());
    let rt = runtime();
    let Some(pool) = rt.block_on(async {
        sqlx::any::install_default_drivers();
        let pool = sqlx::AnyPool::connect(&admin).await.ok()?;
        sqlx::query(sqlx::AssertSqlSafe(format!("DROP DATABASE IF EXISTS {name}"))).execute(&pool).await.unwrap();
        sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}"))).execute(&pool).await.unwrap();
        Some(pool)
    }) else {
        eprintln!("skipping: no PostgreSQL at {admin} (set ANYMO_TEST_POSTGRES)");
        return;
    };
    let url = format!("{}/{name}", admin.rsplit_once('/').unwrap().0);
    let scratch = scratch_dir("server-replicas");
    let env = [("DATABASE_URL", url.as_str())];
    let a = serve(&scratch.join("a"), &models, &[], &env);
    let b = serve(&scratch.join("b"), &models, &[], &env);
    let husky = std::fs::read(shared.join("quaternius/bvh/animals_pack/Husky__Gallop.bvh.gz")).unwrap();
    rt.block_on(async {
        let client = reqwest::Client::new();
        let form = Form::new()
            .text("licence", "CC0-1.0")
            .part("files", file(husky.clone(), "Husky__Gallop.bvh.gz"))
            .part("files", file(b"a husky gallops across the field\n".to_vec(), "Husky__Gallop.txt"));
        let response =
            client.post(format!("{}/v1/ingest", a.base)).bearer_auth(KEY).multipart(form).send().await.unwrap();
        assert_eq!(response.status(), 202);
        let id = response.json::<Value>().await.unwrap()["id"].as_i64().unwrap();
        // Either replica may run the job; both see it end.
        let job = wait_for_job(&client, &b.base, id).await;
        assert_eq!(job["result"]["added"], 1, "{job}");
        let on_a: Value = get_json(&client, format!("{}/v1/clips", a.base)).await;
        let on_b: Value = get_json(&client, format!("{}/v1/clips", b.base)).await;
        assert_eq!(on_a, on_b);
        assert_eq!(on_b.as_array().unwrap().len(), 1);
        for base in [&a.base, &b.base] {
            let page: Value = get_json(&client, format!("{base}/v1/search?q=field&limit=1")).await;
            assert!(page["hits"][0]["path"].as_str().unwrap().ends_with("Husky__Gallop.bvh.gz"), "{base}: {page}");
        }
        // A skeleton stored through A animates on B, and B's result is readable from A.
        let skeletons: Value = get_json(&client, format!("{}/v1/skeletons", b.base)).await;
        let body = serde_json::json!({ "prompt": "a dog gallops", "seconds": 1, "skeleton_id": skeletons[0]["id"] });
        let response = client.post(format!("{}/v1/generate", b.base)).json(&body).send().await.unwrap();
        assert_eq!(response.status(), 200);
        let id = response.headers()["x-generation-id"].to_str().unwrap().to_string();
        let text = response.bytes().await.unwrap();
        let from_a = client.get(format!("{}/v1/generations/{id}/samples/0", a.base)).send().await.unwrap();
        assert_eq!(from_a.bytes().await.unwrap(), text);
    });
    drop((a, b));
    rt.block_on(async {
        sqlx::query(sqlx::AssertSqlSafe(format!("DROP DATABASE {name} WITH (FORCE)"))).execute(&pool).await.unwrap();
    });
}

/// Schemathesis fuzzes every operation of the OpenAPI document (with a key, so writes are
/// reached too) and the server answers no request with a 5xx. Runs when schemathesis is in
/// `target/schemathesis` (`bash tools/setup.sh --test-tools`, as `.ci/run` does) or where
/// `ANYMO_SCHEMATHESIS` says; `ANYMO_SCHEMATHESIS_SECONDS` sets the budget (default 60).
#[test]
fn schemathesis_finds_no_server_error() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let program = std::env::var_os("ANYMO_SCHEMATHESIS").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/schemathesis/bin/schemathesis"),
        PathBuf::from,
    );
    if !test_tool(&program, "schemathesis") {
        return;
    }
    let seconds = std::env::var("ANYMO_SCHEMATHESIS_SECONDS").unwrap_or_else(|_| "60".into());
    let scratch = scratch_dir("server-schemathesis");
    let data = ingested_library(&shared, &models, &scratch);
    let server = serve(&data, &models, &[], &[]);
    let out = Command::new(program)
        .args(["run", &format!("{}/openapi.json", server.base), "--checks", "not_a_server_error"])
        .args(["--max-time", &seconds, "--workers", "2", "-H", &format!("x-api-key: {KEY}")])
        .current_dir(&scratch)
        .output()
        .expect("schemathesis runs");
    let report = String::from_utf8_lossy(&out.stdout);
    // A failed check is listed under FAILURES. Under ERRORS, a "Runtime Error" is schemathesis
    // crashing inside its own Python (CPython's parser has thrown SystemError there), which says
    // nothing about the server; any other error does fail the test.
    assert!(!report.contains("= FAILURES ="), "schemathesis found failures:\n{report}");
    if !out.status.success() {
        let errors = report.split("= ERRORS =").nth(1).unwrap_or_default();
        let entries = errors.lines().filter(|l| l.starts_with("____")).count();
        let crashes = errors.lines().filter(|l| l.trim() == "Runtime Error").count();
        assert!(entries > 0 && entries == crashes, "schemathesis failed:\n{report}");
        eprintln!("schemathesis crashed on {crashes} operation(s) by itself; the server's metrics still decide");
    }
    let cases = report.lines().find(|l| l.contains(" generated, ")).expect("a test-case count");
    assert!(cases.contains("passed") && !cases.contains("failed"), "{cases}");
    let metrics = runtime()
        .block_on(async { reqwest::get(format!("{}/metrics", server.base)).await.unwrap().text().await.unwrap() });
    assert!(!metrics.contains("status=\"5"), "no request was answered 5xx:\n{metrics}");
    eprintln!("schemathesis: {}", cases.trim());
}

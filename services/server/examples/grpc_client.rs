//! A gRPC client of `anymo serve`, as a content tool would use it: checks the server, generates
//! motion for a prompt on a skeleton from a BVH file, writes it, and searches the library.
//!
//! `cargo run --release -p anymo-services --example grpc_client -- http://127.0.0.1:8080 SKELETON.bvh "a dog walks" OUT.bvh`

use anyhow::{Context, Result};
use anymo_server::grpc::proto;
use proto::anymo_client::AnymoClient;

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [server, skeleton, prompt, output] = args.as_slice() else {
        anyhow::bail!("usage: grpc_client SERVER SKELETON.bvh PROMPT OUT.bvh");
    };
    let mut client = AnymoClient::connect(server.clone()).await.with_context(|| format!("connecting to {server}"))?;
    let health = client.health(proto::HealthRequest {}).await?.into_inner();
    println!(
        "server {} ({}): {} clips, {} searchable",
        health.status, health.version, health.clips, health.searchable_clips
    );

    let bvh = std::fs::read_to_string(skeleton).with_context(|| format!("reading {skeleton}"))?;
    let request = proto::GenerateRequest {
        prompt: prompt.clone(),
        seconds: Some(4.0),
        skeleton: Some(proto::generate_request::Skeleton::SkeletonBvh(bvh)),
        sampling: Some(proto::Sampling { samples: Some(1), seed: Some(7), ..Default::default() }),
    };
    let reply = client.generate(request).await?.into_inner();
    std::fs::write(output, &reply.bvh[0]).with_context(|| format!("writing {output}"))?;
    println!("generation {}: {} frames ({} s) written to {output}", reply.generation_id, reply.frames, reply.seconds);

    let found = client
        .search(proto::SearchRequest { text: prompt.clone(), limit: 3, ..Default::default() })
        .await?
        .into_inner();
    for hit in found.hits {
        println!(
            "#{} clip {} {} ({}, {:.1} s): {}",
            hit.rank, hit.clip_id, hit.path, hit.subject, hit.seconds, hit.caption
        );
    }
    Ok(())
}

//! `anymo corpus stats|skeletons|show ID|export ID`: what the store holds.

use super::context::{StoreArgs, runtime};
use anyhow::{Context, Result, bail};
use clap::Subcommand;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
    #[command(flatten)]
    store: StoreArgs,
}

#[derive(Subcommand)]
enum Command {
    /// Counts by source, licence, subject, split and skeleton.
    Stats,
    /// The skeleton catalogue with joint labels.
    Skeletons,
    /// One clip's record and captions.
    Show {
        /// Clip id.
        id: i64,
    },
    /// Write a clip back to BVH, exactly as ingested.
    Export {
        /// Clip id.
        id: i64,
        /// Output .bvh file.
        #[arg(short, long)]
        output: PathBuf,
    },
}

pub fn run(args: Args) -> Result<()> {
    let runtime = runtime()?;
    let store = runtime.block_on(args.store.open())?;
    match args.command {
        Command::Stats => {
            let stats = runtime.block_on(store.stats())?;
            println!("{} clips, {} skeletons, {} captions", stats.clips, stats.skeletons, stats.captions);
            let mut group = String::new();
            for (g, name, clips, frames) in &stats.groups {
                if *g != group {
                    println!("by {g}:");
                    group = g.clone();
                }
                println!("  {name:<32} {clips:>7} clips {frames:>10} frames");
            }
        }
        Command::Skeletons => {
            for s in runtime.block_on(store.skeletons())? {
                println!(
                    "skeleton {}  {} joints  {} clips  fingerprint {}",
                    s.id, s.joint_count, s.clips, s.fingerprint
                );
                println!("  labels: {}", s.labels.join(", "));
            }
        }
        Command::Show { id } => {
            let Some(c) = runtime.block_on(store.clip(id))? else { bail!("no clip {id} in the store") };
            println!("clip {}: {}", c.id, c.source_path);
            println!("  source {}  licence {}  subject {}  split {}", c.source, c.licence, c.subject, c.split);
            println!("  skeleton {}  {} frames at {:.3} fps  hash {}", c.skeleton_id, c.frames, c.fps, c.content_hash);
            for caption in &c.captions {
                println!("  caption: {caption}");
            }
        }
        Command::Export { id, output } => {
            let Some(bytes) = runtime.block_on(store.clip_bvh(id))? else { bail!("no clip {id} in the store") };
            std::fs::write(&output, bytes).with_context(|| format!("writing {}", output.display()))?;
            eprintln!("wrote {}", output.display());
        }
    }
    Ok(())
}

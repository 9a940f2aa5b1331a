//! Ingest: a folder of BVH/GLB files (captions from sidecar `.txt` files, one per line) or a
//! manifest TSV becomes stored clips. Each clip is read, cleaned with the motion core (a clip
//! that cannot be cleaned is rejected with the reason), hashed, and stored with its skeleton,
//! captions and embeddings in one transaction. Known content hashes are skipped, so a run is
//! idempotent, and an interrupted run resumes by running again.

use crate::{NewClip, NewSkeleton, Store, StoreError};
use anymo_motion::bvh::{self, Bvh, ReadOptions};
use anymo_motion::gltf::GltfAsset;
use anymo_motion::motion::Motion;
use anymo_motion::prep::clean::{CleanOptions, clean};
use anymo_motion::prep::labels::label_skeleton;
use anymo_motion::skeleton::{EulerOrder, Skeleton};
use anymo_tokenizer::dataset::split_of;
use anymo_tokenizer::text::{CachedEncoder, TextError};
use std::collections::{BTreeMap, HashSet};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// The frame rate glTF animations are sampled at when ingested.
pub const GLTF_FPS: f64 = 30.0;

/// What went wrong with a whole ingest (single clips are rejected, not errors).
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// The path to ingest cannot be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A manifest line that does not have the manifest's columns.
    #[error("{path} line {line}: {reason}")]
    Manifest {
        /// The manifest.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The store failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The sentence encoder failed.
    #[error(transparent)]
    Text(#[from] TextError),
}

/// One clip to ingest.
#[derive(Clone, Debug)]
pub struct Item {
    /// The clip's identity in the corpus: its path relative to the ingested folder or manifest,
    /// `/`-separated, with `#Animation` for a glTF animation.
    pub key: String,
    /// The file to read.
    pub file: PathBuf,
    /// The glTF animation, for GLB files.
    pub animation: Option<String>,
    /// Source dataset.
    pub source: String,
    /// Licence.
    pub licence: String,
    /// Subject.
    pub subject: String,
    /// Captions.
    pub captions: Vec<String>,
}

/// Lists the clips of a manifest TSV (columns: path, source, license, subject, joints, frames,
/// fps, text with captions separated by ` | `), paths relative to the manifest's folder.
pub fn items_from_manifest(manifest: &Path) -> Result<Vec<Item>, IngestError> {
    let text = std::fs::read_to_string(manifest).map_err(|source| IngestError::Io { path: manifest.into(), source })?;
    let base = manifest.parent().unwrap_or(Path::new("."));
    let mut lines = text.lines().enumerate();
    let header: Vec<&str> = lines.next().map(|(_, l)| l.split('\t').collect()).unwrap_or_default();
    let column = |name: &str| {
        header.iter().position(|h| *h == name).ok_or_else(|| IngestError::Manifest {
            path: manifest.into(),
            line: 1,
            reason: format!("no column {name:?} (found {header:?})"),
        })
    };
    let (path, source, licence, subject, captions) =
        (column("path")?, column("source")?, column("license")?, column("subject")?, column("text")?);
    let mut items = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let cols: Vec<&str> = line.split('\t').collect();
        let get = |c: usize| {
            cols.get(c).copied().ok_or_else(|| IngestError::Manifest {
                path: manifest.into(),
                line: i + 1,
                reason: format!("{} columns, expected {}", cols.len(), header.len()),
            })
        };
        items.push(Item {
            key: get(path)?.to_string(),
            file: base.join(get(path)?),
            animation: None,
            source: get(source)?.to_string(),
            licence: get(licence)?.to_string(),
            subject: get(subject)?.to_string(),
            captions: get(captions)?.split(" | ").map(str::trim).filter(|c| !c.is_empty()).map(String::from).collect(),
        });
    }
    Ok(items)
}

/// Lists the clips of a folder: every `.bvh`, `.bvh.gz` and `.glb` below it (each animation of a
/// GLB is a clip), with captions from a sidecar `.txt` beside the file. The source is the first
/// folder of the path; licence and subject are "unknown".
pub fn items_from_folder(root: &Path) -> Result<Vec<Item>, IngestError> {
    let mut files = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let entries = std::fs::read_dir(&dir).map_err(|source| IngestError::Io { path: dir.clone(), source })?;
        for entry in entries {
            let path = entry.map_err(|source| IngestError::Io { path: dir.clone(), source })?.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.push(path);
            }
        }
    }
    files.sort();
    let mut items = Vec::new();
    for file in files {
        let name = file.to_string_lossy().to_string();
        let stem = if let Some(s) = name.strip_suffix(".bvh.gz") {
            s
        } else if let Some(s) = name.strip_suffix(".bvh") {
            s
        } else if let Some(s) = name.strip_suffix(".glb") {
            s
        } else {
            continue;
        };
        let captions = std::fs::read_to_string(format!("{stem}.txt"))
            .map(|t| t.lines().map(str::trim).filter(|l| !l.is_empty()).map(String::from).collect())
            .unwrap_or_default();
        let key = file.strip_prefix(root).unwrap_or(&file).to_string_lossy().replace('\\', "/");
        let source = key.split('/').next().filter(|_| key.contains('/')).unwrap_or("local").to_string();
        let base = Item {
            key: key.clone(),
            file: file.clone(),
            animation: None,
            source,
            licence: "unknown".into(),
            subject: "unknown".into(),
            captions,
        };
        if name.ends_with(".glb") {
            match GltfAsset::open(&file, EulerOrder::Zxy) {
                Ok(asset) => {
                    for a in asset.animations() {
                        items.push(Item { key: format!("{key}#{}", a.name), animation: Some(a.name), ..base.clone() });
                    }
                }
                // An unreadable GLB is still listed, so the run reports why it was rejected.
                Err(_) => items.push(base),
            }
        } else {
            items.push(base);
        }
    }
    Ok(items)
}

/// A clip read, cleaned and hashed, ready to store.
struct Prepared {
    item: Item,
    content_hash: String,
    bvh_gz: Vec<u8>,
    skeleton: Skeleton,
    fingerprint: String,
    fps: f64,
    frames: usize,
}

/// Reads and checks one clip; the error is the reason it is rejected.
fn prepare(item: &Item) -> Result<Prepared, String> {
    let (clip, content_hash, bvh_gz) = match &item.animation {
        None => {
            let bytes = std::fs::read(&item.file).map_err(|e| format!("cannot read: {e}"))?;
            let text = if bytes.starts_with(&[0x1f, 0x8b]) {
                let mut text = Vec::new();
                flate2::read::MultiGzDecoder::new(bytes.as_slice())
                    .read_to_end(&mut text)
                    .map_err(|e| format!("corrupt gzip: {e}"))?;
                text
            } else {
                bytes.clone()
            };
            let clip = bvh::read(text.as_slice(), ReadOptions { require_motion: true }).map_err(|e| e.to_string())?;
            let gz = if bytes.starts_with(&[0x1f, 0x8b]) { bytes } else { gzip(&text) };
            (clip, blake3::hash(&text).to_hex().to_string(), gz)
        }
        Some(animation) => {
            let asset = GltfAsset::open(&item.file, EulerOrder::Zxy).map_err(|e| e.to_string())?;
            let index = asset.find_animation(animation).map_err(|e| e.to_string())?;
            let motion = asset.motion(index, GLTF_FPS).map_err(|e| e.to_string())?;
            let clip = motion.to_bvh();
            let mut text = Vec::new();
            bvh::write(&clip, &mut text).map_err(|e| e.to_string())?;
            let file = std::fs::read(&item.file).map_err(|e| format!("cannot read: {e}"))?;
            let mut hasher = blake3::Hasher::new();
            hasher.update(&file);
            hasher.update(b"#");
            hasher.update(animation.as_bytes());
            (clip, hasher.finalize().to_hex().to_string(), gzip(&text))
        }
    };
    let motion = Motion::from_bvh(&clip);
    clean(&motion, &CleanOptions::default()).map_err(|r| format!("not usable for models: {r}"))?;
    let skeleton = clip.skeleton().clone();
    Ok(Prepared {
        item: item.clone(),
        content_hash,
        bvh_gz,
        fingerprint: fingerprint(&skeleton),
        skeleton,
        fps: clip.fps(),
        frames: clip.frames(),
    })
}

/// The bytes gzip-compressed, at the fast level.
pub fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut out = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    out.write_all(bytes).expect("writing to memory");
    out.finish().expect("writing to memory")
}

/// The topology fingerprint: a hash of the parent array and the joint names normalised (lower
/// case, letters and digits only), so re-exports with other spacing or case share a skeleton.
pub fn fingerprint(skeleton: &Skeleton) -> String {
    let mut hasher = blake3::Hasher::new();
    for joint in skeleton.joints() {
        let parent = joint.parent.map_or(-1i64, |p| p as i64);
        hasher.update(&parent.to_le_bytes());
        let name: String = joint.name.chars().filter(|c| c.is_alphanumeric()).flat_map(char::to_lowercase).collect();
        hasher.update(name.as_bytes());
        hasher.update(&[0]);
    }
    hasher.finalize().to_hex()[..32].to_string()
}

fn skeleton_only_bvh(skeleton: &Skeleton) -> String {
    let empty = Bvh::new(skeleton.clone(), 1.0 / 30.0, 0, Vec::new()).expect("no frames fit any skeleton");
    let mut text = Vec::new();
    bvh::write(&empty, &mut text).expect("writing to memory");
    String::from_utf8(text).expect("BVH text is UTF-8")
}

/// What a run did.
#[derive(Debug, Default)]
pub struct Summary {
    /// The run's id in the store.
    pub run: i64,
    /// Clips stored.
    pub added: usize,
    /// Clips already stored (same content).
    pub skipped: usize,
    /// Clips not stored, with the reason, grouped by reason.
    pub rejected: BTreeMap<String, Vec<String>>,
}

impl Summary {
    /// The number of rejected clips.
    pub fn rejected_count(&self) -> usize {
        self.rejected.values().map(Vec::len).sum()
    }
}

/// Progress reports while a run goes.
pub trait Progress {
    /// One more clip handled.
    fn clip_done(&self);
}

/// Ingests `items` into `store`, labelled `label` in the run log. Clips are prepared on
/// `threads` threads in chunks; each is stored in its own transaction.
pub async fn ingest(
    store: &Store,
    encoder: &mut CachedEncoder,
    label: &str,
    items: &[Item],
    threads: usize,
    progress: &dyn Progress,
) -> Result<Summary, IngestError> {
    let run = store.start_run(label).await?;
    let mut summary = Summary { run, ..Summary::default() };
    let mut known_skeletons: HashSet<String> = HashSet::new();
    const CHUNK: usize = 64;
    for chunk in items.chunks(CHUNK) {
        let prepared = prepare_all(chunk, threads.max(1));
        // One batch through the encoder for the chunk's captions: the per-clip lookups below
        // then hit the cache (batches of one or two sentences waste the matrix kernels).
        let texts: Vec<&str> =
            prepared.iter().flatten().flat_map(|p| p.item.captions.iter().map(String::as_str)).collect();
        encoder.encode(&texts)?;
        for (item, result) in chunk.iter().zip(prepared) {
            let p = match result {
                Ok(p) => p,
                Err(reason) => {
                    store.record_rejection(run, &item.key, &reason).await?;
                    summary.rejected.entry(reason_kind(&reason)).or_default().push(item.key.clone());
                    progress.clip_done();
                    continue;
                }
            };
            if store.has_clip(&p.content_hash).await? {
                summary.skipped += 1;
                progress.clip_done();
                continue;
            }
            let captions: Vec<&str> = p.item.captions.iter().map(String::as_str).collect();
            let embeddings = encoder.encode(&captions)?;
            let new_skeleton = if known_skeletons.contains(&p.fingerprint) || store.has_skeleton(&p.fingerprint).await?
            {
                None
            } else {
                let labels: Vec<String> = label_skeleton(&p.skeleton).iter().map(|l| l.text()).collect();
                let label_refs: Vec<&str> = labels.iter().map(String::as_str).collect();
                let label_embeddings = encoder.encode(&label_refs)?;
                Some(NewSkeleton {
                    fingerprint: p.fingerprint.clone(),
                    joint_count: p.skeleton.len() as i64,
                    hierarchy: skeleton_only_bvh(&p.skeleton),
                    labels,
                    label_embeddings,
                })
            };
            let clip = NewClip {
                content_hash: p.content_hash.clone(),
                source_path: p.item.key.clone(),
                source: p.item.source.clone(),
                licence: p.item.licence.clone(),
                subject: p.item.subject.clone(),
                fps: p.fps,
                frames: p.frames as i64,
                split: split_of(&p.item.key).as_str().to_string(),
                bvh_gz: p.bvh_gz,
                captions: p.item.captions.iter().cloned().zip(embeddings).collect(),
            };
            store.insert_clip(run, &p.fingerprint, new_skeleton.as_ref(), &clip).await?;
            known_skeletons.insert(p.fingerprint);
            summary.added += 1;
            progress.clip_done();
        }
    }
    store.finish_run(run, summary.added as i64, summary.skipped as i64, summary.rejected_count() as i64).await?;
    Ok(summary)
}

/// Prepares a chunk on several threads, keeping the chunk's order.
fn prepare_all(chunk: &[Item], threads: usize) -> Vec<Result<Prepared, String>> {
    let per_thread = chunk.len().div_ceil(threads);
    std::thread::scope(|scope| {
        let handles: Vec<_> = chunk
            .chunks(per_thread.max(1))
            .map(|part| scope.spawn(move || part.iter().map(prepare).collect::<Vec<_>>()))
            .collect();
        handles.into_iter().flat_map(|h| h.join().expect("a preparing thread panicked")).collect()
    })
}

/// A reason without its numbers, so that the summary groups alike rejections.
fn reason_kind(reason: &str) -> String {
    let mut out = String::with_capacity(reason.len());
    let mut in_number = false;
    for c in reason.chars() {
        if c.is_ascii_digit() || (in_number && c == '.') {
            if !in_number {
                out.push('N');
            }
            in_number = true;
        } else {
            in_number = false;
            out.push(c);
        }
    }
    out
}

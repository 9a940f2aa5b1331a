//! The corpus store: skeletons, clips (with their original bytes), captions and ingest runs, in a
//! SQLite file by default or PostgreSQL through `DATABASE_URL`, by one code path (sqlx's Any
//! driver, `$n` placeholders, times as i64 milliseconds, embeddings as little-endian f32 blobs).

pub mod ingest;
mod server;

pub use server::{Generation, Job, JobFile, JobStatus, NewGeneration};

use sqlx::any::{AnyPoolOptions, AnyRow};
use sqlx::{AnyPool, Row};
use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

static SQLITE_MIGRATIONS: sqlx::migrate::Migrator = sqlx::migrate!("../../migrations/sqlite");
static POSTGRES_MIGRATIONS: sqlx::migrate::Migrator = sqlx::migrate!("../../migrations/postgres");

/// What went wrong with the store.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A database URL that is neither sqlite:// nor postgres://.
    #[error("unsupported database URL {0:?}: use sqlite://PATH or postgres://...")]
    UnsupportedUrl(String),
    /// The database failed.
    #[error("database: {0}")]
    Database(#[from] sqlx::Error),
    /// Bringing the schema up to date failed.
    #[error("migrating the database: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// A stored value that does not decode.
    #[error("corrupt stored value: {0}")]
    Corrupt(String),
}

/// Which database is behind the store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Backend {
    /// An embedded SQLite file.
    Sqlite,
    /// A PostgreSQL server, shareable by several replicas.
    Postgres,
}

/// The corpus store.
#[derive(Clone)]
pub struct Store {
    pool: AnyPool,
}

/// A skeleton to store alongside its first clip.
pub struct NewSkeleton {
    /// Topology fingerprint (parents and normalised names).
    pub fingerprint: String,
    /// Number of joints.
    pub joint_count: i64,
    /// The skeleton as a skeleton-only BVH text.
    pub hierarchy: String,
    /// Semantic label of every joint.
    pub labels: Vec<String>,
    /// Label embeddings, joints x 384.
    pub label_embeddings: Vec<Vec<f32>>,
}

/// A clip to store.
pub struct NewClip {
    /// Content hash: the identity that makes ingest idempotent.
    pub content_hash: String,
    /// The clip's path as given (relative to the ingested folder or manifest).
    pub source_path: String,
    /// Source dataset.
    pub source: String,
    /// Licence identifier.
    pub licence: String,
    /// Subject (species or "person").
    pub subject: String,
    /// Frames per second.
    pub fps: f64,
    /// Number of frames.
    pub frames: i64,
    /// Dataset split.
    pub split: String,
    /// The clip as gzip-compressed BVH.
    pub bvh_gz: Vec<u8>,
    /// Captions with their embeddings.
    pub captions: Vec<(String, Vec<f32>)>,
}

/// Counts of the corpus, grouped.
#[derive(Debug, Default, PartialEq)]
pub struct Stats {
    /// Clips in all.
    pub clips: i64,
    /// Distinct skeletons.
    pub skeletons: i64,
    /// Captions in all.
    pub captions: i64,
    /// (group, name, clips, frames) for groups source, licence, subject, split and skeleton.
    pub groups: Vec<(String, String, i64, i64)>,
}

/// A stored skeleton.
#[derive(Debug)]
pub struct SkeletonRow {
    /// Id.
    pub id: i64,
    /// Topology fingerprint.
    pub fingerprint: String,
    /// Number of joints.
    pub joint_count: i64,
    /// Semantic labels.
    pub labels: Vec<String>,
    /// Skeleton-only BVH.
    pub hierarchy: String,
    /// Clips on this skeleton.
    pub clips: i64,
    /// The sources of its clips, sorted.
    pub sources: Vec<String>,
    /// The subjects of its clips, sorted.
    pub subjects: Vec<String>,
}

/// A stored clip (without its bytes).
#[derive(Debug)]
pub struct ClipRow {
    /// Id.
    pub id: i64,
    /// Path as ingested.
    pub source_path: String,
    /// Skeleton id.
    pub skeleton_id: i64,
    /// Source dataset.
    pub source: String,
    /// Licence.
    pub licence: String,
    /// Subject.
    pub subject: String,
    /// Frames per second.
    pub fps: f64,
    /// Frames.
    pub frames: i64,
    /// Split.
    pub split: String,
    /// Content hash.
    pub content_hash: String,
    /// Captions in order.
    pub captions: Vec<String>,
}

/// What the search index needs of a stored clip.
#[derive(Debug)]
pub struct IndexRecord {
    /// The clip.
    pub clip: ClipRow,
    /// Its skeleton's topology fingerprint.
    pub fingerprint: String,
    /// Its skeleton's joint labels.
    pub joint_labels: Vec<String>,
    /// Embeddings of its captions, in caption order.
    pub caption_embeddings: Vec<Vec<f32>>,
}

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64)
}

/// Little-endian bytes of an f32 array.
pub fn to_blob(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// The f32 array of little-endian bytes written by [`to_blob`].
pub fn from_blob(bytes: &[u8]) -> Vec<f32> {
    bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
}

impl Store {
    /// The default store: a SQLite file in the data directory.
    pub fn default_url(data_dir: &Path) -> String {
        format!("sqlite://{}?mode=rwc", data_dir.join("anymo.db").display())
    }

    /// Opens (creating a SQLite file if needed) and migrates the store at `url`.
    pub async fn open(url: &str) -> Result<Store, StoreError> {
        sqlx::any::install_default_drivers();
        let backend = if url.starts_with("sqlite:") {
            Backend::Sqlite
        } else if url.starts_with("postgres:") || url.starts_with("postgresql:") {
            Backend::Postgres
        } else {
            return Err(StoreError::UnsupportedUrl(url.to_string()));
        };
        if backend == Backend::Sqlite {
            let path = url.trim_start_matches("sqlite://").trim_start_matches("sqlite:");
            let path = path.split('?').next().unwrap_or(path);
            if let Some(dir) = Path::new(path).parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).map_err(|e| StoreError::Database(sqlx::Error::Io(e)))?;
            }
        }
        let pool = AnyPoolOptions::new()
            .max_connections(if backend == Backend::Sqlite { 1 } else { 4 })
            .after_connect(move |conn, _| {
                Box::pin(async move {
                    if backend == Backend::Sqlite {
                        // WAL: readers never block the writer, and a killed process loses
                        // nothing it committed.
                        sqlx::query("PRAGMA journal_mode = WAL").execute(&mut *conn).await?;
                        sqlx::query("PRAGMA synchronous = NORMAL").execute(&mut *conn).await?;
                        sqlx::query("PRAGMA foreign_keys = ON").execute(&mut *conn).await?;
                        sqlx::query("PRAGMA busy_timeout = 10000").execute(&mut *conn).await?;
                    }
                    Ok(())
                })
            })
            .connect(url)
            .await?;
        match backend {
            Backend::Sqlite => SQLITE_MIGRATIONS.run(&pool).await?,
            Backend::Postgres => POSTGRES_MIGRATIONS.run(&pool).await?,
        }
        Ok(Store { pool })
    }

    /// Records the start of an ingest run; runs left `running` by a killed process are marked
    /// `interrupted` first.
    pub async fn start_run(&self, path: &str) -> Result<i64, StoreError> {
        sqlx::query("UPDATE ingest_runs SET status = 'interrupted' WHERE status = 'running'")
            .execute(&self.pool)
            .await?;
        let row =
            sqlx::query("INSERT INTO ingest_runs (path, status, started_ms) VALUES ($1, 'running', $2) RETURNING id")
                .bind(path)
                .bind(now_ms())
                .fetch_one(&self.pool)
                .await?;
        Ok(row.try_get(0)?)
    }

    /// Records how a run ended.
    pub async fn finish_run(&self, run: i64, added: i64, skipped: i64, rejected: i64) -> Result<(), StoreError> {
        sqlx::query(
            "UPDATE ingest_runs SET status = 'done', finished_ms = $1, added = $2, skipped = $3, rejected = $4 WHERE id = $5",
        )
        .bind(now_ms())
        .bind(added)
        .bind(skipped)
        .bind(rejected)
        .bind(run)
        .execute(&self.pool)
        .await?;
        Ok(())
    }

    /// Records a clip that was not stored, and why.
    pub async fn record_rejection(&self, run: i64, path: &str, reason: &str) -> Result<(), StoreError> {
        sqlx::query("INSERT INTO ingest_rejections (run_id, source_path, reason) VALUES ($1, $2, $3)")
            .bind(run)
            .bind(path)
            .bind(reason)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    /// The clips a run did not store, with the reasons, in the order it met them.
    pub async fn rejections(&self, run: i64) -> Result<Vec<(String, String)>, StoreError> {
        sqlx::query("SELECT source_path, reason FROM ingest_rejections WHERE run_id = $1 ORDER BY id")
            .bind(run)
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(|r| Ok((r.try_get(0)?, r.try_get(1)?)))
            .collect()
    }

    /// True when a clip with this content hash is stored.
    pub async fn has_clip(&self, content_hash: &str) -> Result<bool, StoreError> {
        let row = sqlx::query("SELECT COUNT(*) FROM clips WHERE content_hash = $1")
            .bind(content_hash)
            .fetch_one(&self.pool)
            .await?;
        Ok(row.try_get::<i64, _>(0)? > 0)
    }

    /// True when a skeleton with this fingerprint is stored.
    pub async fn has_skeleton(&self, fingerprint: &str) -> Result<bool, StoreError> {
        let row = sqlx::query("SELECT COUNT(*) FROM skeletons WHERE fingerprint = $1")
            .bind(fingerprint)
            .fetch_one(&self.pool)
            .await?;
        Ok(row.try_get::<i64, _>(0)? > 0)
    }

    /// Stores a clip, its captions and (when given and not yet stored) its skeleton, in one
    /// transaction: a clip is stored whole or not at all. Returns the clip id.
    pub async fn insert_clip(
        &self,
        run: i64,
        fingerprint: &str,
        skeleton: Option<&NewSkeleton>,
        clip: &NewClip,
    ) -> Result<i64, StoreError> {
        let mut tx = self.pool.begin().await?;
        if let Some(s) = skeleton {
            let embeddings: Vec<f32> = s.label_embeddings.iter().flatten().copied().collect();
            sqlx::query(
                "INSERT INTO skeletons (fingerprint, joint_count, hierarchy, labels, label_embeddings, created_ms) \
                 VALUES ($1, $2, $3, $4, $5, $6) ON CONFLICT (fingerprint) DO NOTHING",
            )
            .bind(&s.fingerprint)
            .bind(s.joint_count)
            .bind(&s.hierarchy)
            .bind(serde_json::to_string(&s.labels).expect("strings serialise"))
            .bind(to_blob(&embeddings))
            .bind(now_ms())
            .execute(&mut *tx)
            .await?;
        }
        let skeleton_id: i64 = sqlx::query("SELECT id FROM skeletons WHERE fingerprint = $1")
            .bind(fingerprint)
            .fetch_one(&mut *tx)
            .await?
            .try_get(0)?;
        let clip_id: i64 = sqlx::query(
            "INSERT INTO clips (content_hash, source_path, skeleton_id, source, licence, subject, fps, frames, split, \
             bvh_gz, ingest_run, created_ms) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12) RETURNING id",
        )
        .bind(&clip.content_hash)
        .bind(&clip.source_path)
        .bind(skeleton_id)
        .bind(&clip.source)
        .bind(&clip.licence)
        .bind(&clip.subject)
        .bind(clip.fps)
        .bind(clip.frames)
        .bind(&clip.split)
        .bind(&clip.bvh_gz)
        .bind(run)
        .bind(now_ms())
        .fetch_one(&mut *tx)
        .await?
        .try_get(0)?;
        for (position, (text, embedding)) in clip.captions.iter().enumerate() {
            sqlx::query("INSERT INTO captions (clip_id, position, text, embedding) VALUES ($1, $2, $3, $4)")
                .bind(clip_id)
                .bind(position as i64)
                .bind(text)
                .bind(to_blob(embedding))
                .execute(&mut *tx)
                .await?;
        }
        tx.commit().await?;
        Ok(clip_id)
    }

    /// Counts of the corpus by source, licence, subject, split and skeleton.
    pub async fn stats(&self) -> Result<Stats, StoreError> {
        let count = |sql: &'static str| async move {
            let row = sqlx::query(sql).fetch_one(&self.pool).await?;
            Ok::<i64, StoreError>(row.try_get(0)?)
        };
        let mut stats = Stats {
            clips: count("SELECT COUNT(*) FROM clips").await?,
            skeletons: count("SELECT COUNT(*) FROM skeletons").await?,
            captions: count("SELECT COUNT(*) FROM captions").await?,
            groups: Vec::new(),
        };
        let queries: [(&str, &'static str); 5] = [
            (
                "source",
                "SELECT source, COUNT(*), CAST(SUM(frames) AS BIGINT) FROM clips GROUP BY source ORDER BY source",
            ),
            (
                "licence",
                "SELECT licence, COUNT(*), CAST(SUM(frames) AS BIGINT) FROM clips GROUP BY licence ORDER BY licence",
            ),
            (
                "subject",
                "SELECT subject, COUNT(*), CAST(SUM(frames) AS BIGINT) FROM clips GROUP BY subject ORDER BY subject",
            ),
            ("split", "SELECT split, COUNT(*), CAST(SUM(frames) AS BIGINT) FROM clips GROUP BY split ORDER BY split"),
            (
                "skeleton",
                "SELECT CAST(skeleton_id AS TEXT), COUNT(*), CAST(SUM(frames) AS BIGINT) FROM clips GROUP BY skeleton_id ORDER BY skeleton_id",
            ),
        ];
        for (group, sql) in queries {
            for row in sqlx::query(sql).fetch_all(&self.pool).await? {
                stats.groups.push((group.to_string(), row.try_get(0)?, row.try_get(1)?, row.try_get(2)?));
            }
        }
        Ok(stats)
    }

    /// Every skeleton with its clip count.
    pub async fn skeletons(&self) -> Result<Vec<SkeletonRow>, StoreError> {
        let sql = format!("{SKELETON_SELECT} ORDER BY s.id");
        let mut rows: Vec<SkeletonRow> = sqlx::query(sqlx::AssertSqlSafe(sql))
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(skeleton_row)
            .collect::<Result<_, _>>()?;
        let kinds = sqlx::query("SELECT DISTINCT skeleton_id, source, subject FROM clips ORDER BY source, subject")
            .fetch_all(&self.pool)
            .await?;
        for k in &kinds {
            let id: i64 = k.try_get(0)?;
            if let Some(row) = rows.iter_mut().find(|r| r.id == id) {
                add_kind(row, k.try_get(1)?, k.try_get(2)?);
            }
        }
        Ok(rows)
    }

    /// One clip's record and captions.
    pub async fn clip(&self, id: i64) -> Result<Option<ClipRow>, StoreError> {
        let Some(r) = sqlx::query(
            "SELECT id, source_path, skeleton_id, source, licence, subject, fps, frames, split, content_hash \
             FROM clips WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(&self.pool)
        .await?
        else {
            return Ok(None);
        };
        let captions = sqlx::query("SELECT text FROM captions WHERE clip_id = $1 ORDER BY position")
            .bind(id)
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(|c| c.try_get(0))
            .collect::<Result<Vec<String>, _>>()?;
        Ok(Some(clip_row(&r, captions)?))
    }

    /// Every clip id, ascending.
    pub async fn clip_ids(&self) -> Result<Vec<i64>, StoreError> {
        sqlx::query("SELECT id FROM clips ORDER BY id")
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(|r| Ok(r.try_get(0)?))
            .collect()
    }

    /// A clip with its skeleton's fingerprint and labels and its caption embeddings.
    pub async fn index_record(&self, id: i64) -> Result<Option<IndexRecord>, StoreError> {
        let Some(clip) = self.clip(id).await? else { return Ok(None) };
        let skeleton = sqlx::query("SELECT fingerprint, labels FROM skeletons WHERE id = $1")
            .bind(clip.skeleton_id)
            .fetch_one(&self.pool)
            .await?;
        let labels: String = skeleton.try_get(1)?;
        let caption_embeddings = sqlx::query("SELECT embedding FROM captions WHERE clip_id = $1 ORDER BY position")
            .bind(id)
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(|r| Ok(from_blob(&r.try_get::<Vec<u8>, _>(0)?)))
            .collect::<Result<Vec<_>, StoreError>>()?;
        Ok(Some(IndexRecord {
            fingerprint: skeleton.try_get(0)?,
            joint_labels: serde_json::from_str(&labels).map_err(|e| StoreError::Corrupt(e.to_string()))?,
            caption_embeddings,
            clip,
        }))
    }

    /// A clip's BVH text as ingested.
    pub async fn clip_bvh(&self, id: i64) -> Result<Option<Vec<u8>>, StoreError> {
        let Some(row) =
            sqlx::query("SELECT bvh_gz FROM clips WHERE id = $1").bind(id).fetch_optional(&self.pool).await?
        else {
            return Ok(None);
        };
        gunzip(&row.try_get::<Vec<u8>, _>(0)?).map(Some)
    }

    /// Up to `limit` clips with ids above `after`, ascending, with their captions.
    pub async fn list_clips(&self, after: i64, limit: i64) -> Result<Vec<ClipRow>, StoreError> {
        let rows = sqlx::query(
            "SELECT id, source_path, skeleton_id, source, licence, subject, fps, frames, split, content_hash \
             FROM clips WHERE id > $1 ORDER BY id LIMIT $2",
        )
        .bind(after)
        .bind(limit)
        .fetch_all(&self.pool)
        .await?;
        let mut out = Vec::with_capacity(rows.len());
        for r in &rows {
            let id: i64 = r.try_get(0)?;
            let captions = sqlx::query("SELECT text FROM captions WHERE clip_id = $1 ORDER BY position")
                .bind(id)
                .fetch_all(&self.pool)
                .await?
                .iter()
                .map(|c| c.try_get(0))
                .collect::<Result<Vec<String>, _>>()?;
            out.push(clip_row(r, captions)?);
        }
        Ok(out)
    }

    /// One skeleton by id.
    pub async fn skeleton(&self, id: i64) -> Result<Option<SkeletonRow>, StoreError> {
        let sql = format!("{SKELETON_SELECT} WHERE s.id = $1");
        let row = sqlx::query(sqlx::AssertSqlSafe(sql)).bind(id).fetch_optional(&self.pool).await?;
        let Some(mut row) = row.as_ref().map(skeleton_row).transpose()? else { return Ok(None) };
        let kinds =
            sqlx::query("SELECT DISTINCT source, subject FROM clips WHERE skeleton_id = $1 ORDER BY source, subject")
                .bind(id)
                .fetch_all(&self.pool)
                .await?;
        for k in &kinds {
            add_kind(&mut row, k.try_get(0)?, k.try_get(1)?);
        }
        Ok(Some(row))
    }

    /// The first stored clip (lowest id) on a skeleton, if it has any: a pose of the skeleton in
    /// real motion, which generation on a stored skeleton writes its motion around.
    pub async fn first_clip_of_skeleton(&self, skeleton_id: i64) -> Result<Option<i64>, StoreError> {
        let row = sqlx::query("SELECT MIN(id) FROM clips WHERE skeleton_id = $1")
            .bind(skeleton_id)
            .fetch_one(&self.pool)
            .await?;
        Ok(row.try_get::<Option<i64>, _>(0)?)
    }

    /// Deletes a clip and its captions; false when there was no such clip.
    pub async fn delete_clip(&self, id: i64) -> Result<bool, StoreError> {
        let mut tx = self.pool.begin().await?;
        sqlx::query("DELETE FROM captions WHERE clip_id = $1").bind(id).execute(&mut *tx).await?;
        let deleted = sqlx::query("DELETE FROM clips WHERE id = $1").bind(id).execute(&mut *tx).await?.rows_affected();
        tx.commit().await?;
        Ok(deleted > 0)
    }

    /// A cheap signature of the clips stored (count and largest id): it changes whenever a
    /// clip is added or deleted, so a replica can tell when to sync its search index.
    pub async fn clips_signature(&self) -> Result<(i64, i64), StoreError> {
        let row = sqlx::query("SELECT COUNT(*), CAST(COALESCE(MAX(id), 0) AS BIGINT) FROM clips")
            .fetch_one(&self.pool)
            .await?;
        Ok((row.try_get(0)?, row.try_get(1)?))
    }

    /// True when the database answers.
    pub async fn ping(&self) -> Result<(), StoreError> {
        sqlx::query("SELECT 1").execute(&self.pool).await?;
        Ok(())
    }

    /// Every stored clip's content as comparable text lines (path, hash, skeleton fingerprint,
    /// metadata, captions with embeddings), sorted: two stores hold the same corpus exactly when
    /// these are equal, whatever their ids and times.
    pub async fn canonical_dump(&self) -> Result<Vec<String>, StoreError> {
        let rows = sqlx::query(
            "SELECT c.source_path, c.content_hash, s.fingerprint, c.source, c.licence, c.subject, c.fps, c.frames, \
             c.split, c.bvh_gz, c.id, s.labels, s.label_embeddings FROM clips c JOIN skeletons s ON s.id = c.skeleton_id",
        )
        .fetch_all(&self.pool)
        .await?;
        let mut out = Vec::with_capacity(rows.len());
        for r in &rows {
            let id: i64 = r.try_get(10)?;
            let bytes: Vec<u8> = r.try_get(9)?;
            let labels: String = r.try_get(11)?;
            let label_embeddings: Vec<u8> = r.try_get(12)?;
            let captions =
                sqlx::query("SELECT position, text, embedding FROM captions WHERE clip_id = $1 ORDER BY position")
                    .bind(id)
                    .fetch_all(&self.pool)
                    .await?;
            let mut line = format!(
                "{} {} {} {} {} {} {} {} {} bvh:{} labels:{labels} label-emb:{}",
                r.try_get::<String, _>(0)?,
                r.try_get::<String, _>(1)?,
                r.try_get::<String, _>(2)?,
                r.try_get::<String, _>(3)?,
                r.try_get::<String, _>(4)?,
                r.try_get::<String, _>(5)?,
                r.try_get::<f64, _>(6)?,
                r.try_get::<i64, _>(7)?,
                r.try_get::<String, _>(8)?,
                blake3::hash(&bytes),
                blake3::hash(&label_embeddings),
            );
            for c in &captions {
                let emb: Vec<u8> = c.try_get(2)?;
                line.push_str(&format!(
                    " | {} {} {}",
                    c.try_get::<i64, _>(0)?,
                    c.try_get::<String, _>(1)?,
                    blake3::hash(&emb)
                ));
            }
            out.push(line);
        }
        out.sort();
        Ok(out)
    }
}

/// The columns of a [`SkeletonRow`], with its clip count.
const SKELETON_SELECT: &str = "SELECT s.id, s.fingerprint, s.joint_count, s.labels, s.hierarchy, \
     (SELECT COUNT(*) FROM clips c WHERE c.skeleton_id = s.id) FROM skeletons s";

/// Notes one (source, subject) of a skeleton's clips, keeping both lists sorted and distinct.
fn add_kind(row: &mut SkeletonRow, source: String, subject: String) {
    if let Err(at) = row.sources.binary_search(&source) {
        row.sources.insert(at, source);
    }
    if let Err(at) = row.subjects.binary_search(&subject) {
        row.subjects.insert(at, subject);
    }
}

fn skeleton_row(r: &AnyRow) -> Result<SkeletonRow, StoreError> {
    let labels: String = r.try_get(3)?;
    Ok(SkeletonRow {
        id: r.try_get(0)?,
        fingerprint: r.try_get(1)?,
        joint_count: r.try_get(2)?,
        labels: serde_json::from_str(&labels).map_err(|e| StoreError::Corrupt(e.to_string()))?,
        hierarchy: r.try_get(4)?,
        clips: r.try_get(5)?,
        sources: Vec::new(),
        subjects: Vec::new(),
    })
}

/// The bytes of a stored gzip blob.
fn gunzip(gz: &[u8]) -> Result<Vec<u8>, StoreError> {
    let mut text = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::MultiGzDecoder::new(gz), &mut text)
        .map_err(|e| StoreError::Corrupt(format!("stored gzip: {e}")))?;
    Ok(text)
}

fn clip_row(r: &AnyRow, captions: Vec<String>) -> Result<ClipRow, StoreError> {
    Ok(ClipRow {
        id: r.try_get(0)?,
        source_path: r.try_get(1)?,
        skeleton_id: r.try_get(2)?,
        source: r.try_get(3)?,
        licence: r.try_get(4)?,
        subject: r.try_get(5)?,
        fps: r.try_get(6)?,
        frames: r.try_get(7)?,
        split: r.try_get(8)?,
        content_hash: r.try_get(9)?,
        captions,
    })
}

//! What the server keeps in the store besides the corpus: generated results, and long jobs
//! (an uploaded ingest) with their files, status and progress. Jobs are claimed by one replica
//! at a time; a running job whose owner stops reporting is taken over by another.

use super::{Store, StoreError, now_ms};
use sqlx::Row;
use sqlx::any::AnyRow;

/// A generated result to store: the request as JSON and each sample's BVH text.
pub struct NewGeneration<'a> {
    /// What made it: `generate`, `inpaint`, `continue`, `transfer` or `detokenize`.
    pub kind: &'a str,
    /// The request, as JSON.
    pub request: serde_json::Value,
    /// Frames of each sample.
    pub frames: i64,
    /// Frames per second.
    pub fps: f64,
    /// Each sample's BVH text.
    pub samples: &'a [String],
    /// Each sample's quality report, as a JSON array in sample order.
    pub quality: serde_json::Value,
}

/// A stored result (without its samples' bytes).
#[derive(Debug, Clone)]
pub struct Generation {
    /// Id.
    pub id: i64,
    /// What made it.
    pub kind: String,
    /// The request, as JSON.
    pub request: serde_json::Value,
    /// Frames of each sample.
    pub frames: i64,
    /// Frames per second.
    pub fps: f64,
    /// Samples stored.
    pub samples: i64,
    /// Each sample's quality report (a JSON array; `None` for results stored before reports).
    pub quality: Option<serde_json::Value>,
    /// When it was made (ms since the epoch).
    pub created_ms: i64,
}

/// Where a job is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobStatus {
    /// Accepted, waiting for a worker.
    Queued,
    /// A worker is on it.
    Running,
    /// Finished; `result` says what it did.
    Done,
    /// Stopped by an error; `error` says which.
    Failed,
}

impl JobStatus {
    /// The stored word.
    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Done => "done",
            JobStatus::Failed => "failed",
        }
    }

    fn parse(text: &str) -> Result<JobStatus, StoreError> {
        Ok(match text {
            "queued" => JobStatus::Queued,
            "running" => JobStatus::Running,
            "done" => JobStatus::Done,
            "failed" => JobStatus::Failed,
            other => return Err(StoreError::Corrupt(format!("job status {other:?}"))),
        })
    }
}

/// A stored job.
#[derive(Debug, Clone)]
pub struct Job {
    /// Id.
    pub id: i64,
    /// What it does (`ingest`).
    pub kind: String,
    /// Where it is.
    pub status: JobStatus,
    /// Its parameters, as JSON.
    pub params: serde_json::Value,
    /// Items done.
    pub done: i64,
    /// Items in all.
    pub total: i64,
    /// What it did, as JSON, once done.
    pub result: Option<serde_json::Value>,
    /// Why it failed.
    pub error: Option<String>,
    /// When it was accepted and when it last reported (ms since the epoch).
    pub created_ms: i64,
    /// When it last reported.
    pub updated_ms: i64,
}

/// A file uploaded with a job.
#[derive(Debug, Clone)]
pub struct JobFile {
    /// Its name as uploaded.
    pub name: String,
    /// Its captions.
    pub captions: Vec<String>,
    /// Its bytes.
    pub bytes: Vec<u8>,
}

fn json(text: &str) -> Result<serde_json::Value, StoreError> {
    serde_json::from_str(text).map_err(|e| StoreError::Corrupt(format!("stored JSON: {e}")))
}

fn job_row(r: &AnyRow) -> Result<Job, StoreError> {
    let result: Option<String> = r.try_get(6)?;
    Ok(Job {
        id: r.try_get(0)?,
        kind: r.try_get(1)?,
        status: JobStatus::parse(&r.try_get::<String, _>(2)?)?,
        params: json(&r.try_get::<String, _>(3)?)?,
        done: r.try_get(4)?,
        total: r.try_get(5)?,
        result: result.as_deref().map(json).transpose()?,
        error: r.try_get(7)?,
        created_ms: r.try_get(8)?,
        updated_ms: r.try_get(9)?,
    })
}

const JOB_COLUMNS: &str = "id, kind, status, params, done, total, result, error, created_ms, updated_ms";

impl Store {
    /// Stores a generated result and its samples in one transaction; returns its id.
    pub async fn insert_generation(&self, generation: &NewGeneration<'_>) -> Result<i64, StoreError> {
        let mut tx = self.pool.begin().await?;
        let id: i64 = sqlx::query(
            "INSERT INTO generations (kind, request, frames, fps, created_ms, quality) VALUES ($1, $2, $3, $4, $5, $6) \
             RETURNING id",
        )
        .bind(generation.kind)
        .bind(generation.request.to_string())
        .bind(generation.frames)
        .bind(generation.fps)
        .bind(now_ms())
        .bind(generation.quality.to_string())
        .fetch_one(&mut *tx)
        .await?
        .try_get(0)?;
        for (position, bvh) in generation.samples.iter().enumerate() {
            sqlx::query("INSERT INTO generation_samples (generation_id, position, bvh_gz) VALUES ($1, $2, $3)")
                .bind(id)
                .bind(position as i64)
                .bind(crate::ingest::gzip(bvh.as_bytes()))
                .execute(&mut *tx)
                .await?;
        }
        tx.commit().await?;
        Ok(id)
    }

    /// A stored result's record.
    pub async fn generation(&self, id: i64) -> Result<Option<Generation>, StoreError> {
        let Some(r) = sqlx::query(
            "SELECT g.id, g.kind, g.request, g.frames, g.fps, g.created_ms, \
             (SELECT COUNT(*) FROM generation_samples s WHERE s.generation_id = g.id), g.quality \
             FROM generations g WHERE g.id = $1",
        )
        .bind(id)
        .fetch_optional(&self.pool)
        .await?
        else {
            return Ok(None);
        };
        Ok(Some(Generation {
            id: r.try_get(0)?,
            kind: r.try_get(1)?,
            request: json(&r.try_get::<String, _>(2)?)?,
            frames: r.try_get(3)?,
            fps: r.try_get(4)?,
            created_ms: r.try_get(5)?,
            samples: r.try_get(6)?,
            quality: r.try_get::<Option<String>, _>(7)?.map(|q| json(&q)).transpose()?,
        }))
    }

    /// One sample of a stored result, as BVH text.
    pub async fn generation_sample(&self, id: i64, position: i64) -> Result<Option<Vec<u8>>, StoreError> {
        let Some(row) = sqlx::query("SELECT bvh_gz FROM generation_samples WHERE generation_id = $1 AND position = $2")
            .bind(id)
            .bind(position)
            .fetch_optional(&self.pool)
            .await?
        else {
            return Ok(None);
        };
        super::gunzip(&row.try_get::<Vec<u8>, _>(0)?).map(Some)
    }

    /// Accepts a job with its files, queued, in one transaction; returns its id.
    pub async fn insert_job(
        &self,
        kind: &str,
        params: &serde_json::Value,
        files: &[JobFile],
    ) -> Result<i64, StoreError> {
        let mut tx = self.pool.begin().await?;
        let now = now_ms();
        let id: i64 = sqlx::query(
            "INSERT INTO jobs (kind, status, params, total, created_ms, updated_ms) VALUES ($1, 'queued', $2, $3, $4, $4) \
             RETURNING id",
        )
        .bind(kind)
        .bind(params.to_string())
        .bind(files.len() as i64)
        .bind(now)
        .fetch_one(&mut *tx)
        .await?
        .try_get(0)?;
        for (position, file) in files.iter().enumerate() {
            sqlx::query("INSERT INTO job_files (job_id, position, name, captions, bytes) VALUES ($1, $2, $3, $4, $5)")
                .bind(id)
                .bind(position as i64)
                .bind(&file.name)
                .bind(serde_json::to_string(&file.captions).expect("strings serialise"))
                .bind(&file.bytes)
                .execute(&mut *tx)
                .await?;
        }
        tx.commit().await?;
        Ok(id)
    }

    /// A job's record.
    pub async fn job(&self, id: i64) -> Result<Option<Job>, StoreError> {
        let sql = format!("SELECT {JOB_COLUMNS} FROM jobs WHERE id = $1");
        let row = sqlx::query(sqlx::AssertSqlSafe(sql)).bind(id).fetch_optional(&self.pool).await?;
        row.as_ref().map(job_row).transpose()
    }

    /// A job's files, in upload order.
    pub async fn job_files(&self, id: i64) -> Result<Vec<JobFile>, StoreError> {
        sqlx::query("SELECT name, captions, bytes FROM job_files WHERE job_id = $1 ORDER BY position")
            .bind(id)
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(|r| {
                let captions: String = r.try_get(1)?;
                Ok(JobFile {
                    name: r.try_get(0)?,
                    captions: serde_json::from_str(&captions).map_err(|e| StoreError::Corrupt(e.to_string()))?,
                    bytes: r.try_get(2)?,
                })
            })
            .collect()
    }

    /// Claims the oldest job for `owner`: a queued one, or a running one whose owner has not
    /// reported for `stale_ms` (its process died). Two replicas never claim the same job.
    pub async fn claim_job(&self, owner: &str, stale_ms: i64) -> Result<Option<Job>, StoreError> {
        loop {
            let now = now_ms();
            let candidate = sqlx::query(
                "SELECT id, updated_ms FROM jobs WHERE status = 'queued' OR (status = 'running' AND updated_ms < $1) \
                 ORDER BY id LIMIT 1",
            )
            .bind(now - stale_ms)
            .fetch_optional(&self.pool)
            .await?;
            let Some(candidate) = candidate else { return Ok(None) };
            let (id, seen): (i64, i64) = (candidate.try_get(0)?, candidate.try_get(1)?);
            // The update only wins if nobody touched the job since it was read.
            let claimed = sqlx::query(
                "UPDATE jobs SET status = 'running', owner = $1, updated_ms = $2 WHERE id = $3 AND updated_ms = $4 \
                 AND status IN ('queued', 'running')",
            )
            .bind(owner)
            .bind(now.max(seen + 1))
            .bind(id)
            .bind(seen)
            .execute(&self.pool)
            .await?
            .rows_affected();
            if claimed == 1 {
                return self.job(id).await;
            }
        }
    }

    /// Puts back in the queue the jobs `owner` was running: its process died with them.
    pub async fn requeue_jobs_of(&self, owner: &str) -> Result<u64, StoreError> {
        Ok(sqlx::query("UPDATE jobs SET status = 'queued', updated_ms = $1 WHERE status = 'running' AND owner = $2")
            .bind(now_ms())
            .bind(owner)
            .execute(&self.pool)
            .await?
            .rows_affected())
    }

    /// Reports a running job's progress (and that its owner is alive).
    pub async fn job_progress(&self, id: i64, done: i64) -> Result<(), StoreError> {
        sqlx::query("UPDATE jobs SET done = $1, updated_ms = $2 WHERE id = $3 AND status = 'running'")
            .bind(done)
            .bind(now_ms())
            .bind(id)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    /// Ends a job: done with a result, or failed with an error. Its files are dropped.
    pub async fn finish_job(
        &self,
        id: i64,
        outcome: Result<&serde_json::Value, &str>,
        done: i64,
    ) -> Result<(), StoreError> {
        let mut tx = self.pool.begin().await?;
        let (status, result, error) = match outcome {
            Ok(result) => (JobStatus::Done, Some(result.to_string()), None),
            Err(error) => (JobStatus::Failed, None, Some(error.to_string())),
        };
        sqlx::query("UPDATE jobs SET status = $1, result = $2, error = $3, done = $4, updated_ms = $5 WHERE id = $6")
            .bind(status.as_str())
            .bind(result)
            .bind(error)
            .bind(done)
            .bind(now_ms())
            .bind(id)
            .execute(&mut *tx)
            .await?;
        sqlx::query("DELETE FROM job_files WHERE job_id = $1").bind(id).execute(&mut *tx).await?;
        tx.commit().await?;
        Ok(())
    }
}

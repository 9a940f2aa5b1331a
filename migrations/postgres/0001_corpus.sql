-- The motion corpus: skeletons (deduplicated by topology), clips with their original bytes,
-- captions with embeddings, and the ingest runs that added them. Times are milliseconds since
-- the Unix epoch; embeddings are little-endian f32 arrays.
CREATE TABLE skeletons (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    fingerprint TEXT NOT NULL UNIQUE,
    joint_count BIGINT NOT NULL,
    hierarchy TEXT NOT NULL,
    labels TEXT NOT NULL,
    label_embeddings BYTEA NOT NULL,
    created_ms BIGINT NOT NULL
);

CREATE TABLE ingest_runs (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    path TEXT NOT NULL,
    status TEXT NOT NULL,
    started_ms BIGINT NOT NULL,
    finished_ms BIGINT,
    added BIGINT NOT NULL DEFAULT 0,
    skipped BIGINT NOT NULL DEFAULT 0,
    rejected BIGINT NOT NULL DEFAULT 0
);

CREATE TABLE clips (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    content_hash TEXT NOT NULL UNIQUE,
    source_path TEXT NOT NULL,
    skeleton_id BIGINT NOT NULL REFERENCES skeletons (id),
    source TEXT NOT NULL,
    licence TEXT NOT NULL,
    subject TEXT NOT NULL,
    fps DOUBLE PRECISION NOT NULL,
    frames BIGINT NOT NULL,
    split TEXT NOT NULL,
    bvh_gz BYTEA NOT NULL,
    ingest_run BIGINT NOT NULL REFERENCES ingest_runs (id),
    created_ms BIGINT NOT NULL
);
CREATE INDEX clips_skeleton ON clips (skeleton_id);
CREATE INDEX clips_source ON clips (source);

CREATE TABLE captions (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    clip_id BIGINT NOT NULL REFERENCES clips (id) ON DELETE CASCADE,
    position BIGINT NOT NULL,
    text TEXT NOT NULL,
    embedding BYTEA NOT NULL,
    UNIQUE (clip_id, position)
);

CREATE TABLE ingest_rejections (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    run_id BIGINT NOT NULL REFERENCES ingest_runs (id),
    source_path TEXT NOT NULL,
    reason TEXT NOT NULL
);

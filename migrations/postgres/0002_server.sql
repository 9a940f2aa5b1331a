-- What the server keeps: every generated result (the request and each sample's BVH), and long
-- jobs (an uploaded ingest) with their status, progress and uploaded files, so a job survives
-- the process that accepted it. Times are milliseconds since the Unix epoch.
CREATE TABLE generations (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    kind TEXT NOT NULL,
    request TEXT NOT NULL,
    frames BIGINT NOT NULL,
    fps DOUBLE PRECISION NOT NULL,
    created_ms BIGINT NOT NULL
);

CREATE TABLE generation_samples (
    generation_id BIGINT NOT NULL REFERENCES generations (id) ON DELETE CASCADE,
    position BIGINT NOT NULL,
    bvh_gz BYTEA NOT NULL,
    PRIMARY KEY (generation_id, position)
);

CREATE TABLE jobs (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    kind TEXT NOT NULL,
    status TEXT NOT NULL,
    params TEXT NOT NULL,
    done BIGINT NOT NULL DEFAULT 0,
    total BIGINT NOT NULL DEFAULT 0,
    result TEXT,
    error TEXT,
    owner TEXT,
    created_ms BIGINT NOT NULL,
    updated_ms BIGINT NOT NULL
);
CREATE INDEX jobs_status ON jobs (status);

CREATE TABLE job_files (
    job_id BIGINT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    position BIGINT NOT NULL,
    name TEXT NOT NULL,
    captions TEXT NOT NULL,
    bytes BYTEA NOT NULL,
    PRIMARY KEY (job_id, position)
);

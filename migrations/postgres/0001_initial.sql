-- The calibration service's store on PostgreSQL: the same schema as migrations/sqlite (a test,
-- tests/postgres_schema.rs, compares the two table by table), in PostgreSQL's dialect. Documents
-- are kept as the JSON text the files use (TEXT, not jsonb: the bytes stored are the bytes read
-- back, as on SQLite). Times are RFC 3339 UTC strings with milliseconds (TEXT: they sort as text,
-- bytewise under the C collation the database is created with); ids are UUIDv7 strings.
-- SQLite's INTEGER flags are BOOLEAN here, its INTEGER counts BIGINT, its REAL DOUBLE PRECISION.

CREATE TABLE robots (
    id                      TEXT PRIMARY KEY,
    name                    TEXT NOT NULL UNIQUE,
    model_json              TEXT NOT NULL,
    base_guess_json         TEXT,
    -- REFERENCES parameter_sets (id): added below, once that table exists.
    active_parameter_set_id TEXT,
    created_at              TEXT NOT NULL
);

CREATE TABLE artefacts (
    id         TEXT PRIMARY KEY,
    name       TEXT NOT NULL UNIQUE,
    spec_json  TEXT NOT NULL,
    created_at TEXT NOT NULL
);

CREATE TABLE sessions (
    id           TEXT PRIMARY KEY,
    robot_id     TEXT NOT NULL REFERENCES robots (id),
    name         TEXT NOT NULL,
    purpose      TEXT NOT NULL CHECK (purpose IN ('identification', 'validation')),
    instrument   TEXT NOT NULL CHECK (instrument IN ('trical', 'laser_tracker')),
    tool_json    TEXT NOT NULL,
    identify_tcp BOOLEAN NOT NULL DEFAULT FALSE,
    artefact_id  TEXT REFERENCES artefacts (id),
    created_at   TEXT NOT NULL,
    UNIQUE (robot_id, name)
);

CREATE TABLE batches (
    id              TEXT PRIMARY KEY,
    session_id      TEXT NOT NULL REFERENCES sessions (id),
    idempotency_key TEXT,
    request_hash    TEXT NOT NULL,
    first_seq       BIGINT NOT NULL,
    count           BIGINT NOT NULL,
    created_at      TEXT NOT NULL,
    UNIQUE (session_id, idempotency_key)
);

CREATE TABLE measurements (
    session_id TEXT NOT NULL REFERENCES sessions (id),
    seq        BIGINT NOT NULL,
    batch_id   TEXT NOT NULL REFERENCES batches (id),
    spec_json  TEXT NOT NULL,
    PRIMARY KEY (session_id, seq)
);

CREATE TABLE jobs (
    id               TEXT PRIMARY KEY,
    kind             TEXT NOT NULL CONSTRAINT jobs_kind_check CHECK (kind IN ('pose_plan', 'identification', 'validation')),
    robot_id         TEXT NOT NULL REFERENCES robots (id),
    state            TEXT NOT NULL CHECK (state IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    progress         DOUBLE PRECISION NOT NULL DEFAULT 0,
    request_json     TEXT NOT NULL,
    result_json      TEXT,
    error_json       TEXT,
    attempts         BIGINT NOT NULL DEFAULT 0,
    lease_owner      TEXT,
    lease_expires_at TEXT,
    cancel_requested BOOLEAN NOT NULL DEFAULT FALSE,
    created_at       TEXT NOT NULL,
    started_at       TEXT,
    finished_at      TEXT,
    updated_at       TEXT NOT NULL
);
CREATE INDEX jobs_by_state ON jobs (state, created_at);
CREATE INDEX jobs_by_robot ON jobs (robot_id, created_at);

CREATE TABLE parameter_sets (
    id            TEXT PRIMARY KEY,
    robot_id      TEXT NOT NULL REFERENCES robots (id),
    version       BIGINT NOT NULL,
    doc_json      TEXT NOT NULL,
    sessions_json TEXT NOT NULL,
    job_id        TEXT REFERENCES jobs (id),
    created_at    TEXT NOT NULL,
    UNIQUE (robot_id, version)
);

ALTER TABLE robots ADD CONSTRAINT robots_active_parameter_set_id_fkey
    FOREIGN KEY (active_parameter_set_id) REFERENCES parameter_sets (id);

CREATE TABLE validations (
    id               TEXT PRIMARY KEY,
    parameter_set_id TEXT NOT NULL REFERENCES parameter_sets (id),
    sessions_json    TEXT NOT NULL,
    report_json      TEXT NOT NULL,
    job_id           TEXT REFERENCES jobs (id),
    created_at       TEXT NOT NULL
);
CREATE INDEX validations_by_set ON validations (parameter_set_id, created_at);

CREATE TABLE pose_plans (
    id           TEXT PRIMARY KEY,
    robot_id     TEXT NOT NULL REFERENCES robots (id),
    request_json TEXT NOT NULL,
    result_json  TEXT NOT NULL,
    job_id       TEXT REFERENCES jobs (id),
    created_at   TEXT NOT NULL
);

-- Bearer tokens: only the SHA-256 of the secret is stored.
CREATE TABLE tokens (
    id         TEXT PRIMARY KEY,
    name       TEXT NOT NULL,
    hash       TEXT NOT NULL UNIQUE,
    scopes     TEXT NOT NULL,
    created_at TEXT NOT NULL,
    revoked_at TEXT
);

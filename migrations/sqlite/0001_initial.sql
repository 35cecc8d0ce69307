-- The calibration service's store. Documents are kept as the JSON the files use (mm, deg, units
-- in the field names), so a cell exported from the store and a cell file are the same thing.
-- Times are RFC 3339 UTC strings with milliseconds; ids are UUIDv7 strings (time-ordered).

CREATE TABLE robots (
    id                      TEXT PRIMARY KEY,
    name                    TEXT NOT NULL UNIQUE,
    -- {"preset": "irb120"} or a custom table, as accepted (see README "Files").
    model_json              TEXT NOT NULL,
    -- T_0^W guess {"x_mm", …, "c_deg"} or NULL (then identification registers the base).
    base_guess_json         TEXT,
    active_parameter_set_id TEXT REFERENCES parameter_sets (id),
    created_at              TEXT NOT NULL
);

CREATE TABLE artefacts (
    id         TEXT PRIMARY KEY,
    name       TEXT NOT NULL UNIQUE,
    -- {"kind": "ball_triangle", "distances_mm": {…}, "ball_diameter_mm": …}
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
    identify_tcp INTEGER NOT NULL DEFAULT 0,
    artefact_id  TEXT REFERENCES artefacts (id),
    created_at   TEXT NOT NULL,
    UNIQUE (robot_id, name)
);

-- One appended batch of measurements: all its rows or none. The idempotency key makes a retried
-- upload return the first answer instead of appending twice.
CREATE TABLE batches (
    id              TEXT PRIMARY KEY,
    session_id      TEXT NOT NULL REFERENCES sessions (id),
    idempotency_key TEXT,
    request_hash    TEXT NOT NULL,
    first_seq       INTEGER NOT NULL,
    count           INTEGER NOT NULL,
    created_at      TEXT NOT NULL,
    UNIQUE (session_id, idempotency_key)
);

CREATE TABLE measurements (
    session_id TEXT NOT NULL REFERENCES sessions (id),
    -- 0-based position in the session, dense: the measurement's index everywhere else.
    seq        INTEGER NOT NULL,
    batch_id   TEXT NOT NULL REFERENCES batches (id),
    -- {"joints_deg": […], "ball": k | "position_mm": […], …} as in cell files.
    spec_json  TEXT NOT NULL,
    PRIMARY KEY (session_id, seq)
) WITHOUT ROWID;

CREATE TABLE jobs (
    id               TEXT PRIMARY KEY,
    kind             TEXT NOT NULL CHECK (kind IN ('pose_plan', 'identification', 'validation')),
    robot_id         TEXT NOT NULL REFERENCES robots (id),
    state            TEXT NOT NULL CHECK (state IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    progress         REAL NOT NULL DEFAULT 0,
    request_json     TEXT NOT NULL,
    -- Where the result lives ({"parameter_set_id": …} and a summary), once succeeded.
    result_json      TEXT,
    -- A problem document ({"type", "title", "detail", …}), once failed.
    error_json       TEXT,
    attempts         INTEGER NOT NULL DEFAULT 0,
    lease_owner      TEXT,
    lease_expires_at TEXT,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    created_at       TEXT NOT NULL,
    started_at       TEXT,
    finished_at      TEXT,
    updated_at       TEXT NOT NULL
);
CREATE INDEX jobs_by_state ON jobs (state, created_at);
CREATE INDEX jobs_by_robot ON jobs (robot_id, created_at);

-- Immutable once written; a robot's versions count 1, 2, 3 …
CREATE TABLE parameter_sets (
    id            TEXT PRIMARY KEY,
    robot_id      TEXT NOT NULL REFERENCES robots (id),
    version       INTEGER NOT NULL,
    -- The parameter-set file (values, nominal, std, units, status, quality).
    doc_json      TEXT NOT NULL,
    -- [{"id": …, "name": …, "measurements": n}] of the sessions identified from.
    sessions_json TEXT NOT NULL,
    job_id        TEXT REFERENCES jobs (id),
    created_at    TEXT NOT NULL,
    UNIQUE (robot_id, version)
);

CREATE TABLE validations (
    id               TEXT PRIMARY KEY,
    parameter_set_id TEXT NOT NULL REFERENCES parameter_sets (id),
    sessions_json    TEXT NOT NULL,
    -- The validation statistics (calibrated and nominal), residuals included.
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
    -- Space-separated: measure calibrate compensate read admin.
    scopes     TEXT NOT NULL,
    created_at TEXT NOT NULL,
    revoked_at TEXT
);

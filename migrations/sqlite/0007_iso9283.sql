-- ISO 9283 evaluations (issue 26): the pose characteristics of a measured session run as a job
-- and are stored beside the robot.

-- jobs.kind must admit 'iso9283': the table is rebuilt as in 0002 (SQLite cannot alter a CHECK
-- constraint), with 0006's `phase` column kept. `db::migrate` runs this with foreign-key
-- enforcement off and runs `PRAGMA foreign_key_check` before committing.
CREATE TABLE jobs_new (
    id               TEXT PRIMARY KEY,
    kind             TEXT NOT NULL CHECK (kind IN ('pose_plan', 'identification', 'validation', 'diagnosis', 'iso9283')),
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
    updated_at       TEXT NOT NULL,
    phase            TEXT
);
INSERT INTO jobs_new (id, kind, robot_id, state, progress, request_json, result_json, error_json, attempts,
                      lease_owner, lease_expires_at, cancel_requested, created_at, started_at, finished_at,
                      updated_at, phase)
    SELECT id, kind, robot_id, state, progress, request_json, result_json, error_json, attempts,
           lease_owner, lease_expires_at, cancel_requested, created_at, started_at, finished_at, updated_at,
           phase
    FROM jobs;
DROP TABLE jobs;
ALTER TABLE jobs_new RENAME TO jobs;
CREATE INDEX jobs_by_state ON jobs (state, created_at);
CREATE INDEX jobs_by_robot ON jobs (robot_id, created_at);

-- An ISO 9283 evaluation of a session: written once by its job.
CREATE TABLE iso9283_evaluations (
    id               TEXT PRIMARY KEY,
    robot_id         TEXT NOT NULL REFERENCES robots (id),
    session_id       TEXT NOT NULL REFERENCES sessions (id),
    -- The calibrated model's set; NULL: the nominal model only.
    parameter_set_id TEXT REFERENCES parameter_sets (id),
    -- The job's request as stored (the session and the set as ids, the pose assignment, the pairs).
    request_json     TEXT NOT NULL,
    -- The evaluation ({"session", "nominal", "calibrated"}), mm and deg.
    report_json      TEXT NOT NULL,
    job_id           TEXT REFERENCES jobs (id),
    created_at       TEXT NOT NULL
);
CREATE INDEX iso9283_by_robot ON iso9283_evaluations (robot_id, created_at);

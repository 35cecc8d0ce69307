-- Diagnoses (issue 11): the sim-to-real diagnosis of a parameter set runs as a job and is stored
-- beside the set; accepting it creates a new parameter set.

-- jobs.kind must admit 'diagnosis'. SQLite cannot alter a CHECK constraint, so the table is
-- rebuilt (SQLite's "other kinds of table schema changes" procedure): a new table with the same
-- columns and the widened CHECK, the rows copied, the old table dropped, the new one renamed and
-- its indexes recreated. `db::migrate` runs this with foreign-key enforcement off (the tables that
-- reference jobs(id) would forbid the DROP otherwise; their REFERENCES clauses name `jobs` and so
-- point at the rebuilt table) and runs `PRAGMA foreign_key_check` before committing.
CREATE TABLE jobs_new (
    id               TEXT PRIMARY KEY,
    kind             TEXT NOT NULL CHECK (kind IN ('pose_plan', 'identification', 'validation', 'diagnosis')),
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
INSERT INTO jobs_new (id, kind, robot_id, state, progress, request_json, result_json, error_json, attempts,
                      lease_owner, lease_expires_at, cancel_requested, created_at, started_at, finished_at,
                      updated_at)
    SELECT id, kind, robot_id, state, progress, request_json, result_json, error_json, attempts,
           lease_owner, lease_expires_at, cancel_requested, created_at, started_at, finished_at, updated_at
    FROM jobs;
DROP TABLE jobs;
ALTER TABLE jobs_new RENAME TO jobs;
CREATE INDEX jobs_by_state ON jobs (state, created_at);
CREATE INDEX jobs_by_robot ON jobs (robot_id, created_at);

-- A diagnosis of a parameter set: written once by its job; `accepted_parameter_set_id` is set
-- once, when it is accepted.
CREATE TABLE diagnoses (
    id                        TEXT PRIMARY KEY,
    parameter_set_id          TEXT NOT NULL REFERENCES parameter_sets (id),
    -- The job's request as stored (options; sessions as ids).
    request_json              TEXT NOT NULL,
    -- {"identification": [names…], "validation": [names…]}
    sessions_json             TEXT NOT NULL,
    -- The diagnosis report (verdict, decomposition, where, candidates, shrink, …), mm and deg.
    report_json               TEXT NOT NULL,
    -- The parameter-set file accepting creates (the extended model fitted on the pooled
    -- sessions); NULL when no effect was named.
    accepted_doc_json         TEXT,
    -- The parameter set accepting created, once accepted.
    accepted_parameter_set_id TEXT REFERENCES parameter_sets (id),
    job_id                    TEXT REFERENCES jobs (id),
    created_at                TEXT NOT NULL
);
CREATE INDEX diagnoses_by_set ON diagnoses (parameter_set_id, created_at);

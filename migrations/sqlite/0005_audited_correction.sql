-- Audited correction (issue 14, item 4): stored data are corrected by records, never silently.

-- A measurement left out of every job that loads its session (identification, validation,
-- diagnosis) and of the exported cell, with who, when and why. Restoring it closes the record,
-- with who, when and why; a measurement has at most one open exclusion, and closed ones stay as
-- its history. `*_by` is the bearer token's name, NULL when the server took the request without
-- a token (loopback).
CREATE TABLE measurement_exclusions (
    id             TEXT PRIMARY KEY,
    session_id     TEXT NOT NULL,
    seq            INTEGER NOT NULL,
    reason         TEXT NOT NULL CHECK (length(trim(reason)) > 0),
    excluded_by    TEXT,
    excluded_at    TEXT NOT NULL,
    restore_reason TEXT CHECK (restore_reason IS NULL OR length(trim(restore_reason)) > 0),
    restored_by    TEXT,
    restored_at    TEXT,
    CHECK ((restored_at IS NULL) = (restore_reason IS NULL)),
    FOREIGN KEY (session_id, seq) REFERENCES measurements (session_id, seq)
);
CREATE UNIQUE INDEX measurement_exclusions_open ON measurement_exclusions (session_id, seq) WHERE restored_at IS NULL;
CREATE INDEX measurement_exclusions_by_measurement ON measurement_exclusions (session_id, seq, excluded_at);

-- A parameter set archived: hidden from the robot's history unless asked for, never activated
-- again. The set itself (and the activations it had) is never deleted.
ALTER TABLE parameter_sets ADD COLUMN archived_at TEXT;
ALTER TABLE parameter_sets ADD COLUMN archived_by TEXT;
ALTER TABLE parameter_sets ADD COLUMN archive_reason TEXT
    CHECK (archive_reason IS NULL OR length(trim(archive_reason)) > 0);

-- Every activation of a parameter set, so that "this set was active from … to …" stays true
-- after the robot moves on and the set is archived. `activated_by` is the token's name (NULL
-- without a token), `job_id` the identification job that activated its own result. The set
-- active when this step ran is recorded with an unknown time (NULL): it was activated before
-- activations were recorded.
CREATE TABLE parameter_set_activations (
    id               TEXT PRIMARY KEY,
    robot_id         TEXT NOT NULL REFERENCES robots (id),
    parameter_set_id TEXT NOT NULL REFERENCES parameter_sets (id),
    activated_at     TEXT,
    activated_by     TEXT,
    job_id           TEXT REFERENCES jobs (id)
);
CREATE INDEX parameter_set_activations_by_robot ON parameter_set_activations (robot_id, activated_at);
INSERT INTO parameter_set_activations (id, robot_id, parameter_set_id, activated_at)
    SELECT 'before-0005-' || id, id, active_parameter_set_id, NULL FROM robots WHERE active_parameter_set_id IS NOT NULL;

-- Every correction, in one timeline: who (token name, NULL without a token), when, what, why,
-- and what the subject was (a deleted session's name, purpose and measurement count, …). The
-- subject's id carries no foreign key: deleted subjects keep their events.
CREATE TABLE audit_events (
    id          TEXT PRIMARY KEY,
    at          TEXT NOT NULL,
    actor       TEXT,
    action      TEXT NOT NULL CHECK (action IN ('measurement_excluded', 'measurement_restored', 'session_deleted',
                                                'artefact_deleted', 'parameter_set_archived',
                                                'parameter_set_unarchived')),
    robot_id    TEXT REFERENCES robots (id),
    subject_id  TEXT NOT NULL,
    reason      TEXT NOT NULL CHECK (length(trim(reason)) > 0),
    detail_json TEXT NOT NULL
);
CREATE INDEX audit_events_by_time ON audit_events (at, id);
CREATE INDEX audit_events_by_robot ON audit_events (robot_id, at);

-- Re-uploads: the SHA-256 of a batch's measurements as stored (their canonical JSON, in order),
-- so the same measurements sent again without an Idempotency-Key — as JSON or as CSV, however
-- spaced — are recognised. NULL for batches stored before this step: the check hashes their rows
-- when it needs to.
ALTER TABLE batches ADD COLUMN content_hash TEXT;
CREATE INDEX batches_by_content ON batches (session_id, content_hash);

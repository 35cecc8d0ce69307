-- ISO 9283 evaluations (issue 26); see migrations/sqlite/0007. PostgreSQL alters the CHECK in
-- place (SQLite had to rebuild the table).
ALTER TABLE jobs DROP CONSTRAINT jobs_kind_check;
ALTER TABLE jobs ADD CONSTRAINT jobs_kind_check
    CHECK (kind IN ('pose_plan', 'identification', 'validation', 'diagnosis', 'iso9283'));

CREATE TABLE iso9283_evaluations (
    id               TEXT PRIMARY KEY,
    robot_id         TEXT NOT NULL REFERENCES robots (id),
    session_id       TEXT NOT NULL REFERENCES sessions (id),
    parameter_set_id TEXT REFERENCES parameter_sets (id),
    request_json     TEXT NOT NULL,
    report_json      TEXT NOT NULL,
    job_id           TEXT REFERENCES jobs (id),
    created_at       TEXT NOT NULL
);
CREATE INDEX iso9283_by_robot ON iso9283_evaluations (robot_id, created_at);

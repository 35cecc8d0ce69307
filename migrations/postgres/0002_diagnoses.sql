-- Diagnoses (issue 11); see migrations/sqlite/0002. PostgreSQL alters the CHECK in place (SQLite
-- had to rebuild the table).
ALTER TABLE jobs DROP CONSTRAINT jobs_kind_check;
ALTER TABLE jobs ADD CONSTRAINT jobs_kind_check
    CHECK (kind IN ('pose_plan', 'identification', 'validation', 'diagnosis'));

CREATE TABLE diagnoses (
    id                        TEXT PRIMARY KEY,
    parameter_set_id          TEXT NOT NULL REFERENCES parameter_sets (id),
    request_json              TEXT NOT NULL,
    sessions_json             TEXT NOT NULL,
    report_json               TEXT NOT NULL,
    accepted_doc_json         TEXT,
    accepted_parameter_set_id TEXT REFERENCES parameter_sets (id),
    job_id                    TEXT REFERENCES jobs (id),
    created_at                TEXT NOT NULL
);
CREATE INDEX diagnoses_by_set ON diagnoses (parameter_set_id, created_at);

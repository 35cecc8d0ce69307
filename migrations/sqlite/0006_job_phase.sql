-- What a running job is doing now ("identifying", "cross-validating candidates", …), beside its
-- progress fraction; the last phase stays after the job ends (a failed job shows where it failed).
ALTER TABLE jobs ADD COLUMN phase TEXT;

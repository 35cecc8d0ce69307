-- What a running job is doing now; see migrations/sqlite/0006.
ALTER TABLE jobs ADD COLUMN phase TEXT;

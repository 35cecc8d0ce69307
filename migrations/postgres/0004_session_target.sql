-- One TCP per physical target (issue 13, item 1); see migrations/sqlite/0004.
ALTER TABLE sessions ADD COLUMN target TEXT CHECK (target IS NULL OR length(trim(target)) > 0);

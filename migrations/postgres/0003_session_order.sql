-- Measuring order (issue 13, item 4); see migrations/sqlite/0003.
ALTER TABLE sessions ADD COLUMN measuring_order TEXT NOT NULL DEFAULT 'unknown'
    CHECK (measuring_order IN ('measured', 'shuffled', 'resampled', 'unknown'));

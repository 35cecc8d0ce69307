-- Measuring order (issue 13, item 4): whether a session's measurements are listed as measured.
-- Backlash directions are derived from consecutive measurements only when they are consecutive
-- stops, so a session says whether its measurements are `measured` in order, `shuffled` after
-- measuring, `resampled` from measured sessions, or `unknown` (every session stored before this
-- step). Each measurement's own `sequence` number, like its `time_s`, lives in its spec_json.
ALTER TABLE sessions ADD COLUMN measuring_order TEXT NOT NULL DEFAULT 'unknown'
    CHECK (measuring_order IN ('measured', 'shuffled', 'resampled', 'unknown'));

-- One TCP per physical target (issue 13, item 1): sessions whose TCP is identified get a TCP each,
-- unless they name the same physical target (one reflector measured on two days), which then
-- shares one TCP. NULL (every session stored before this step) is a target of its own.
ALTER TABLE sessions ADD COLUMN target TEXT CHECK (target IS NULL OR length(trim(target)) > 0);

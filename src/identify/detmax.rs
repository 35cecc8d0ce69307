//! DETMAX pose selection (Mitchell 1974; thesis §4.2.5).

//! Measurement pose generation (thesis §4.1, digest §8).

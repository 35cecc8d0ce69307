//! The sim-to-real diagnosis (issue 11): where the calibrated model still misses, which physical
//! effect it is missing, and how far the held-out error shrinks once that effect is added.
//! Pure math, like `identify/`: no I/O.

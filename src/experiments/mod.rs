//! Studies on the virtual cell that exercise the whole pipeline (simulate → identify →
//! diagnose): above the pure-math layers, below the front ends.

pub mod withheld;

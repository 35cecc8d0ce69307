//! Observability indices O1–O5 (digest §6).

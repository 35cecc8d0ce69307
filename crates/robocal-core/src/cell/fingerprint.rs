//! Fingerprints of measurements' content: what tells the measurements a parameter set was fitted
//! on from other measurements that carry the same session name (every three-reflector import names
//! its sessions `reflector-1`, `reflector-2`, …, so a calibration run and a validation run imported
//! apart have sessions of one name and different data).
//!
//! One fingerprint per measurement: SHA-256 of its joint readings and observed position, rounded to
//! 1e-12 rad and 0.1 nm (so that the readings' conversions on two paths — a file, the service's
//! store — cannot tell a measurement from itself), written as 16 hexadecimal digits (its first 64
//! bits: two different readings share one with a probability of 5e-20). Indices play no part: the
//! service numbers a session's measurements as stored and a job's cell without the excluded ones,
//! and the same reading must be known under either numbering.

use nalgebra::Vector3;
use sha2::{Digest, Sha256};

use super::{Cell, Measurement};

/// The fingerprint of one reading: joint readings in rad, observed position in {W} in m.
pub fn of_reading(q: &[f64], p: &Vector3<f64>) -> String {
    let mut h = Sha256::new();
    h.update((q.len() as u64).to_le_bytes());
    for v in q {
        h.update(rounded(*v, 1e-12).to_le_bytes());
    }
    for v in p.iter() {
        h.update(rounded(*v, 1e-10).to_le_bytes());
    }
    h.finalize()[..8].iter().map(|b| format!("{b:02x}")).collect()
}

/// The fingerprint of a cell's measurement, as [`of_reading`]; `None` when its position is not
/// known (a ball of a cell without its artefact).
pub fn of_measurement(cell: &Cell, m: &Measurement) -> Option<String> {
    Some(of_reading(&m.q, &cell.observed_position(m)?))
}

/// `v` in whole `unit`s (saturating beyond ±9.2e18 units; NaN reads 0).
fn rounded(v: f64, unit: f64) -> i64 {
    (v / unit).round() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_readings_equal_fingerprints_and_any_change_shows() {
        let q = [0.1, -0.2, 0.3];
        let p = Vector3::new(1.0, 2.0, 3.0);
        let a = of_reading(&q, &p);
        assert_eq!(a.len(), 16);
        assert!(a.chars().all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase()));
        // A conversion's last bit is not a different reading.
        assert_eq!(a, of_reading(&[0.1 + 1e-16, -0.2, 0.3], &p));
        // A micrometre, a microradian, a joint more: another fingerprint.
        assert_ne!(a, of_reading(&q, &Vector3::new(1.0, 2.0, 3.000001)));
        assert_ne!(a, of_reading(&[0.1, -0.200001, 0.3], &p));
        assert_ne!(a, of_reading(&[0.1, -0.2, 0.3, 0.0], &p));
    }
}

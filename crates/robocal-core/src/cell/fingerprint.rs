//! A fingerprint of measurements' content: what tells the measurements a parameter set was fitted
//! on from other measurements that carry the same session name (every three-reflector import names
//! its sessions `reflector-1`, `reflector-2`, …, so a calibration run and a validation run imported
//! apart have sessions of one name and different data).
//!
//! SHA-256 over each measurement's index, joint readings and observed position, rounded to
//! 1e-12 rad and 0.1 nm (so that the readings' conversions on two paths — a file, the service's
//! store — cannot tell a measurement from itself), written as 32 hexadecimal digits (its first
//! 128 bits).

use nalgebra::Vector3;
use sha2::{Digest, Sha256};

use super::{Cell, Session};

/// The fingerprint of `entries`: (index in its session, joint readings in rad, observed position
/// in {W} in m), in the order given.
pub fn of_entries<'a>(entries: impl IntoIterator<Item = (usize, &'a [f64], Vector3<f64>)>) -> String {
    let mut h = Sha256::new();
    let mut count: u64 = 0;
    for (index, q, p) in entries {
        h.update((index as u64).to_le_bytes());
        h.update((q.len() as u64).to_le_bytes());
        for v in q {
            h.update(rounded(*v, 1e-12).to_le_bytes());
        }
        for v in p.iter() {
            h.update(rounded(*v, 1e-10).to_le_bytes());
        }
        count += 1;
    }
    h.update(count.to_le_bytes());
    h.finalize()[..16].iter().map(|b| format!("{b:02x}")).collect()
}

/// The fingerprint of `session`'s measurements at `indices` (ascending), as [`of_entries`]; `None`
/// when an index lies beyond the session or a measurement's position is not known (a ball of a
/// cell without its artefact).
pub fn of_session(cell: &Cell, session: &Session, indices: &[usize]) -> Option<String> {
    let entries = indices
        .iter()
        .map(|&i| {
            let m = session.measurements.get(i)?;
            Some((i, &m.q[..], cell.observed_position(m)?))
        })
        .collect::<Option<Vec<_>>>()?;
    Some(of_entries(entries))
}

/// `v` in whole `unit`s (saturating beyond ±9.2e18 units; NaN reads 0).
fn rounded(v: f64, unit: f64) -> i64 {
    (v / unit).round() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_content_equal_fingerprint_and_any_change_shows() {
        let q = [0.1, -0.2, 0.3];
        let p = Vector3::new(1.0, 2.0, 3.0);
        let a = of_entries([(0, &q[..], p), (1, &q[..], p)]);
        assert_eq!(a.len(), 32);
        // A conversion's last bit is not a different reading.
        let q2 = [0.1 + 1e-16, -0.2, 0.3];
        assert_eq!(a, of_entries([(0, &q2[..], p), (1, &q[..], p)]));
        // A micrometre, a microradian, an index, a reading fewer: another fingerprint.
        let moved = Vector3::new(1.0, 2.0, 3.000001);
        assert_ne!(a, of_entries([(0, &q[..], p), (1, &q[..], moved)]));
        let turned = [0.1, -0.200001, 0.3];
        assert_ne!(a, of_entries([(0, &q[..], p), (1, &turned[..], p)]));
        assert_ne!(a, of_entries([(0, &q[..], p), (2, &q[..], p)]));
        assert_ne!(a, of_entries([(0, &q[..], p)]));
    }
}

//! Candidate pools shared by the tests of the DETMAX modules.

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::Block;

pub(super) fn random_pool(rng: &mut ChaCha8Rng, n: usize, rows: usize, m: usize) -> Vec<Block> {
    let scales: Vec<f64> = (0..m).map(|_| 10f64.powf(rng.random_range(-3.0..1.0))).collect();
    (0..n)
        .map(|_| Block::new(rows, (0..rows * m).map(|k| rng.random_range(-1.0..1.0) * scales[k % m]).collect()))
        .collect()
}

/// W = Σ_w B_wᵀB_w of a workspace's blocks, m × m row-major (units of the blocks).
pub(super) fn workspace_info(blocks: &[Block], m: usize) -> Vec<f64> {
    let mut w = DMatrix::<f64>::zeros(m, m);
    for b in blocks {
        let j = DMatrix::from_row_slice(b.rows, m, &b.data);
        w += j.transpose() * j;
    }
    (0..m * m).map(|k| w[(k / m, k % m)]).collect()
}

pub(super) fn to_dmatrix(a: &[f64], m: usize) -> DMatrix<f64> {
    DMatrix::from_row_slice(m, m, a)
}

/// Blocks of the thesis's IRB 120 (Table 5.1, TriCal tool): position rows of the 31 identified
/// parameters (SI) at random configurations within the joint limits.
pub(super) fn realistic_pool(count: usize, seed: u64) -> Vec<Block> {
    realistic_pool_within(count, seed, 1.0)
}

/// [`realistic_pool`] with every joint drawn within the central `share` of its range: a pool
/// confined to part of the workspace, as the TriCal's candidates near the balls are.
pub(super) fn realistic_pool_within(count: usize, seed: u64, share: f64) -> Vec<Block> {
    use crate::kinematics::thesis::{irb120_table_5_1, trical_tool};
    use crate::kinematics::{JointState, Rows};
    let names = [
        "alpha1", "alpha2", "alpha3", "alpha4", "alpha5", "a1", "a2", "a3", "a4", "a5", "d3", "d4", "d5", "d6",
        "theta2", "theta3", "theta4", "theta5", "theta6", "c2", "c3", "c4", "c5", "c6", "beta2", "base_x", "base_y",
        "base_z", "base_a", "base_b", "base_c",
    ];
    let set = irb120_table_5_1(trical_tool());
    let (chain, gravity) = (set.chain(), set.gravity());
    let cols: Vec<usize> = names.iter().map(|n| set.layout.find(n).unwrap()).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut buf = vec![0.0; 3 * set.layout.len()];
    let mut out = Vec::new();
    while out.len() < count {
        let q: Vec<f64> = set
            .model
            .links
            .iter()
            .map(|l| {
                let (mid, half) = (0.5 * (l.limits[0] + l.limits[1]), 0.5 * share * (l.limits[1] - l.limits[0]));
                rng.random_range(mid - half..mid + half)
            })
            .collect();
        if q[4].abs() < 0.05 {
            continue;
        }
        let s = JointState::with_torques(&q, &gravity.torques(&q)[..6]);
        chain.jacobian_into(&s, &set.layout, Rows::Position, &mut buf, 3);
        out.push(Block::from_column_major(&buf, 3, 3, &cols));
    }
    out
}

//! Reference values published in the thesis (Gaudreault 2016), for tests, examples and the
//! virtual cell's default truth.

use nalgebra::Vector3;

use super::model::{Tool, irb120};
use super::param_set::ParameterSet;
use super::params::Param;

/// The TriCal measuring tool (Table 3.4: 1.7 kg, CoM (30, 0, 64) mm) with its TCP — the centre of
/// the constrained ball — at (40, 0, 130) mm in the flange frame, off axis 6 as §2.2.1 requires.
pub fn trical_tool() -> Tool {
    Tool { tcp: [0.040, 0.0, 0.130, 0.0, 0.0, 0.0], mass: 1.7, com: Vector3::new(0.030, 0.0, 0.064) }
}

/// Table 5.1: the nominal base of the IRB 120 cell (x, y, z mm; α, β, γ deg).
pub const TABLE_5_1_NOMINAL_BASE: [f64; 6] = [160.211, -255.727, -220.548, 91.603, 0.496, -1.384];

/// Table 5.1: mean identified values over 30 DETMAX sets of 75 configurations, in file units
/// (mm, deg, deg/(N·m)).
pub const TABLE_5_1_MEANS: [(&str, f64); 31] = [
    ("alpha1", -90.034),
    ("alpha2", -0.045),
    ("alpha3", -90.011),
    ("alpha4", 89.998),
    ("alpha5", -89.990),
    ("a1", 0.013),
    ("a2", 270.146),
    ("a3", 70.120),
    ("a4", -0.075),
    ("a5", -0.012),
    ("d3", -0.094),
    ("d4", 302.296),
    ("d5", 0.019),
    ("d6", 72.163),
    ("theta2", -89.910),
    ("theta3", 0.097),
    ("theta4", -0.013),
    ("theta5", 0.062),
    ("theta6", 180.259),
    ("c2", -2.060e-3),
    ("c3", -5.522e-3),
    ("c4", -33.738e-3),
    ("c5", -30.448e-3),
    ("c6", -44.555e-3),
    ("beta2", 0.039),
    ("base_x", 158.865),
    ("base_y", -253.835),
    ("base_z", -219.170),
    ("base_a", 91.677),
    ("base_b", 0.148),
    ("base_c", -1.380),
];

/// The IRB 120 as the thesis identified it (Table 5.1 means) carrying `tool`; nominal values are
/// the robot's table and the cell's nominal base.
pub fn irb120_table_5_1(tool: Tool) -> ParameterSet {
    let b = TABLE_5_1_NOMINAL_BASE;
    let base = [b[0] * 1e-3, b[1] * 1e-3, b[2] * 1e-3, b[3].to_radians(), b[4].to_radians(), b[5].to_radians()];
    let mut set = ParameterSet::nominal(irb120(), tool, base);
    for (name, v) in TABLE_5_1_MEANS {
        let p = Param::parse(name).expect("Table 5.1 names are parameter names");
        assert!(set.set(p, v * p.unit().to_si()), "{name} is an IRB 120 parameter");
    }
    set
}

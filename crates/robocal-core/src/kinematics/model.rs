//! Robot structure: a serial chain of revolute joints in Craig's modified DH, any joint optionally
//! carrying Hayati's β, with joint limits, link masses and centres of mass, and the gravity vector.
//!
//! Everything here is in SI units (m, rad, kg, m/s²). The wire format (mm, deg) is converted once,
//! in the service's `domain` module.

use nalgebra::Vector3;

use super::frame::rot_x;
use crate::units::{DEG, MM};

/// The largest chain the fixed-size kernels handle. Industrial arms have 6 or 7 joints.
pub const MAX_JOINTS: usize = 8;

/// Standard gravity magnitude, m/s².
pub(crate) const STANDARD_GRAVITY: f64 = 9.80665;

/// One row of the modified DH table (link `i`, joint `i`):
/// `T_i^{i−1} = Rx(α_{i−1}) · Tx(a_{i−1}) · [Ry(β_{i−1})] · Rz(θ_i) · Tz(d_i)` with θ_i = q_i + theta.
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    /// α_{i−1}, rad.
    pub alpha: f64,
    /// a_{i−1}, m.
    pub a: f64,
    /// Joint zero offset (θ_i = q_i + theta), rad.
    pub theta: f64,
    /// d_i, m.
    pub d: f64,
    /// Hayati's β_{i−1}, rad; `Some` for a joint whose axis is (nearly) parallel to the previous one.
    pub beta: Option<f64>,
    /// Lower and upper joint limits of q_i, rad.
    pub limits: [f64; 2],
    /// Link mass, kg.
    pub mass: f64,
    /// Centre of mass in the link's own frame {i}, m.
    pub com: Vector3<f64>,
}

/// A robot's nominal structure.
#[derive(Clone, Debug, PartialEq)]
pub struct RobotModel {
    /// Preset name or a user-given name.
    pub name: String,
    /// `Some(preset)` when the model is a built-in preset, so files can refer to it by name.
    pub preset: Option<Preset>,
    /// Rows of the modified DH table, joint 1 first (1 to [`MAX_JOINTS`]).
    pub links: Vec<Link>,
    /// Gravity acceleration expressed in the base frame {0}, m/s².
    pub gravity: Vector3<f64>,
}

/// A tool: the TCP frame in the flange frame plus the payload it puts on the flange.
#[derive(Clone, Debug, PartialEq)]
pub struct Tool {
    /// T_T^6 as χ = (x, y, z, a, b, c): metres and ZY'X'' radians.
    pub tcp: [f64; 6],
    /// Payload mass, kg.
    pub mass: f64,
    /// Payload centre of mass in the flange frame {n}, m.
    pub com: Vector3<f64>,
}

impl Tool {
    /// A massless tool at the flange origin.
    pub fn flange() -> Self {
        Self { tcp: [0.0; 6], mass: 0.0, com: Vector3::zeros() }
    }
}

/// Built-in robot models.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Preset {
    /// ABB IRB 120 ([`irb120`]), name `irb120`.
    Irb120,
    /// Universal Robots UR10, CB3 ([`ur10`]), name `ur10`.
    Ur10,
}

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 2] = [Preset::Irb120, Preset::Ur10];

    /// The name files use for the preset.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Irb120 => "irb120",
            Preset::Ur10 => "ur10",
        }
    }

    /// The preset of a name; `None` for an unknown name.
    pub fn from_name(name: &str) -> Option<Preset> {
        Preset::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The preset's nominal model.
    pub fn model(self) -> RobotModel {
        match self {
            Preset::Irb120 => irb120(),
            Preset::Ur10 => ur10(),
        }
    }
}

/// Why a robot model is not usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// The number of joints is not between 1 and [`MAX_JOINTS`].
    #[error("a robot needs between 1 and {MAX_JOINTS} joints, got {0}")]
    JointCount(usize),
    /// A bad value in one joint's row.
    #[error("joints[{joint}].{field}: {reason}")]
    Field {
        /// Joint index, 0-based.
        joint: usize,
        /// The offending field of [`Link`] (`alpha`, `d`, `limits` …).
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The gravity vector is not finite.
    #[error("gravity: {0}")]
    Gravity(String),
}

impl RobotModel {
    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.links.len()
    }

    /// Check the structural invariants the kinematics rely on.
    pub fn validate(&self) -> Result<(), ModelError> {
        let n = self.links.len();
        if n == 0 || n > MAX_JOINTS {
            return Err(ModelError::JointCount(n));
        }
        for (j, l) in self.links.iter().enumerate() {
            let bad =
                |field: &'static str, reason: &str| ModelError::Field { joint: j, field, reason: reason.to_string() };
            for (field, v) in [("alpha", l.alpha), ("a", l.a), ("theta", l.theta), ("d", l.d), ("mass", l.mass)] {
                if !v.is_finite() {
                    return Err(bad(field, "must be a finite number"));
                }
            }
            if let Some(b) = l.beta
                && !b.is_finite()
            {
                return Err(bad("beta", "must be a finite number"));
            }
            if l.com.iter().any(|v| !v.is_finite()) {
                return Err(bad("com", "must be finite"));
            }
            if l.mass < 0.0 {
                return Err(bad("mass", "must not be negative"));
            }
            let [lo, hi] = l.limits;
            if lo.is_nan() || hi.is_nan() || lo >= hi {
                return Err(bad("limits", "lower limit must be below the upper limit"));
            }
        }
        if self.gravity.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::Gravity("must be finite".into()));
        }
        Ok(())
    }

    /// Whether joint `j` (0-based) is within its limits at `q` (rad).
    pub fn within_limits(&self, j: usize, q: f64) -> bool {
        let [lo, hi] = self.links[j].limits;
        q >= lo && q <= hi
    }
}

/// ABB IRB 120: thesis Table 3.1 (geometry), Table 3.4 (masses and centres of mass) and the
/// joint limits of the product specification. Hayati's β on joint 3 (axes 2 and 3 are parallel).
pub fn irb120() -> RobotModel {
    // (α_{i−1} °, a_{i−1} mm, θ offset °, d_i mm, β?, limits °, mass kg, CoM mm)
    #[allow(clippy::type_complexity)]
    let rows: [(f64, f64, f64, f64, bool, [f64; 2], f64, [f64; 3]); 6] = [
        (0.0, 0.0, 0.0, 290.0, false, [-165.0, 165.0], 6.0, [0.0, 0.0, -3.0]),
        (-90.0, 0.0, -90.0, 0.0, false, [-110.0, 110.0], 4.2, [140.0, 0.0, 0.0]),
        (0.0, 270.0, 0.0, 0.0, true, [-110.0, 70.0], 3.2, [50.0, 40.0, 0.0]),
        (-90.0, 70.0, 0.0, 302.0, false, [-160.0, 160.0], 1.8, [0.0, 0.0, -72.0]),
        (90.0, 0.0, 0.0, 0.0, false, [-120.0, 120.0], 1.2, [0.0, 10.0, 0.0]),
        (-90.0, 0.0, 180.0, 72.0, false, [-400.0, 400.0], 0.2, [0.0, 0.0, 0.0]),
    ];
    RobotModel {
        name: "irb120".into(),
        preset: Some(Preset::Irb120),
        links: rows
            .iter()
            .map(|&(al, a, th, d, beta, lim, m, c)| Link {
                alpha: al * DEG,
                a: a * MM,
                theta: th * DEG,
                d: d * MM,
                beta: beta.then_some(0.0),
                limits: [lim[0] * DEG, lim[1] * DEG],
                mass: m,
                com: Vector3::new(c[0], c[1], c[2]) * MM,
            })
            .collect(),
        gravity: Vector3::new(0.0, 0.0, -STANDARD_GRAVITY),
    }
}

/// One row of a standard (distal) DH table: `Rz(θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)`,
/// with the link's centre of mass in its standard-DH frame (at the distal end of the link).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct StandardDhRow {
    /// Joint zero offset (θ_i = q_i + theta), rad.
    pub theta: f64,
    /// d_i, m.
    pub d: f64,
    /// a_i, m.
    pub a: f64,
    /// α_i, rad.
    pub alpha: f64,
    /// Lower and upper joint limits of q_i, rad.
    pub limits: [f64; 2],
    /// Link mass, kg.
    pub mass: f64,
    /// Centre of mass in the standard-DH link frame i, m.
    pub com: Vector3<f64>,
}

/// Exact conversion of a standard DH chain to Craig's modified convention.
///
/// The standard product `Π Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i)` regroups, because Tx and Rx commute,
/// as `Rz(θ_1) Tz(d_1) · Π_{i≥2} [Rx(α_{i−1}) Tx(a_{i−1}) Rz(θ_i) Tz(d_i)] · Tx(a_n) Rx(α_n)`.
/// So the modified row i takes α_{i−1} and a_{i−1} of the standard row i−1 (zero for row 1),
/// and the trailing `Tx(a_n) Rx(α_n)` is the frame between the modified flange {n} and the
/// standard flange: returned as a pose χ so that tools can be re-expressed exactly. Each centre of
/// mass moves from the standard frame i (distal) to the modified frame i (proximal):
/// `p_mod = Tx(a_i) · Rx(α_i) · p_std`. `beta_joints` lists (0-based) joints to give a Hayati β.
pub(crate) fn modified_from_standard(rows: &[StandardDhRow], beta_joints: &[usize]) -> (Vec<Link>, [f64; 6]) {
    let mut links = Vec::with_capacity(rows.len());
    for (i, row) in rows.iter().enumerate() {
        let (alpha, a) = if i == 0 { (0.0, 0.0) } else { (rows[i - 1].alpha, rows[i - 1].a) };
        let com = rot_x(row.alpha) * row.com + Vector3::new(row.a, 0.0, 0.0);
        links.push(Link {
            alpha,
            a,
            theta: row.theta,
            d: row.d,
            beta: beta_joints.contains(&i).then_some(0.0),
            limits: row.limits,
            mass: row.mass,
            com,
        });
    }
    let last = rows.last().expect("a chain has at least one row");
    // Tx(a_n) Rx(α_n) as χ: translation (a_n, 0, 0), ZY'X'' angles (0, 0, α_n).
    (links, [last.a, 0.0, 0.0, 0.0, 0.0, last.alpha])
}

/// The UR10 (CB3) standard DH table of `../shared/datasets/ur10-ipa/README.md`, with link masses
/// and centres of mass from Universal Robots' published dynamics parameters ("DH parameters for
/// calculations of kinematics and dynamics", CB3 UR10), expressed in the standard-DH link frames.
pub(crate) fn ur10_standard_dh() -> Vec<StandardDhRow> {
    let half_pi = std::f64::consts::FRAC_PI_2;
    // (d mm, a mm, α rad, mass kg, CoM m)
    let rows: [(f64, f64, f64, f64, [f64; 3]); 6] = [
        (127.3, 0.0, half_pi, 7.1, [0.021, 0.0, 0.027]),
        (0.0, -612.0, 0.0, 12.7, [0.38, 0.0, 0.158]),
        (0.0, -572.3, 0.0, 4.27, [0.24, 0.0, 0.068]),
        (163.941, 0.0, half_pi, 2.0, [0.0, 0.007, 0.018]),
        (115.7, 0.0, -half_pi, 2.0, [0.0, 0.007, 0.018]),
        (92.2, 0.0, 0.0, 0.365, [0.0, 0.0, -0.026]),
    ];
    rows.iter()
        .map(|&(d, a, alpha, mass, c)| StandardDhRow {
            theta: 0.0,
            d: d * MM,
            a: a * MM,
            alpha,
            limits: [-2.0 * std::f64::consts::PI, 2.0 * std::f64::consts::PI],
            mass,
            com: Vector3::new(c[0], c[1], c[2]),
        })
        .collect()
}

/// Universal Robots UR10 in the modified convention, converted exactly from its standard DH
/// table. Axes 2, 3 and 4 are parallel: joints 3 and 4 carry Hayati's β (`beta2`, `beta3`).
/// The standard and modified flange frames coincide (a_6 = 0, α_6 = 0).
pub fn ur10() -> RobotModel {
    let (links, flange) = modified_from_standard(&ur10_standard_dh(), &[2, 3]);
    debug_assert!(flange.iter().all(|v| *v == 0.0));
    RobotModel {
        name: "ur10".into(),
        preset: Some(Preset::Ur10),
        links,
        gravity: Vector3::new(0.0, 0.0, -STANDARD_GRAVITY),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid() {
        for p in Preset::ALL {
            let m = p.model();
            m.validate().unwrap();
            assert_eq!(m.dof(), 6);
            assert_eq!(Preset::from_name(p.name()), Some(p));
        }
    }

    #[test]
    fn irb120_table_3_1() {
        let m = irb120();
        assert!((m.links[1].theta + 90.0 * DEG).abs() < 1e-15);
        assert!((m.links[5].theta - 180.0 * DEG).abs() < 1e-15);
        assert!((m.links[3].d - 0.302).abs() < 1e-15);
        assert_eq!(m.links.iter().filter(|l| l.beta.is_some()).count(), 1);
        assert!(m.links[2].beta.is_some());
    }

    /// The modified-DH UR10 against the standard-DH product Π Rz(θ)·Tz(d)·Tx(a)·Rx(α) on random
    /// configurations: same flange pose, and the same centres of mass in the world.
    #[test]
    fn ur10_conversion_preserves_forward_kinematics() {
        use crate::kinematics::frame::{Frame, rot_z};
        use crate::kinematics::{JointState, ParameterSet};
        use rand::{Rng, SeedableRng};
        let std_rows = ur10_standard_dh();
        let model = ur10();
        let chain = ParameterSet::nominal(model.clone(), Tool::flange(), [0.0; 6]).nominal_chain();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        for _ in 0..500 {
            let q: Vec<f64> = (0..6).map(|_| rng.random_range(-6.2..6.2)).collect();
            let mut t = Frame::identity();
            let mut com_std = Vec::new();
            for (row, &qi) in std_rows.iter().zip(&q) {
                t = t
                    .compose(&Frame::new(rot_z(qi + row.theta), Vector3::new(0.0, 0.0, row.d)))
                    .compose(&Frame::new(rot_x(row.alpha), Vector3::new(row.a, 0.0, 0.0)));
                com_std.push(t.transform_point(&row.com));
            }
            let theta: Vec<f64> = (0..6).map(|j| q[j] + model.links[j].theta).collect();
            let mut th = [0.0; MAX_JOINTS];
            th[..6].copy_from_slice(&theta);
            let tr = chain.trace(&th);
            let f = chain.fk(&JointState::new(&q));
            assert!((f.t - t.t).norm() < 1e-14 && (f.r - t.r).abs().max() < 1e-14);
            for j in 0..6 {
                let c_mod = tr.link_frame(j).transform_point(&model.links[j].com);
                assert!((c_mod - com_std[j]).norm() < 1e-14, "link {j}");
            }
        }
    }

    #[test]
    fn invalid_models_are_refused() {
        let mut m = irb120();
        m.links[2].limits = [1.0, -1.0];
        assert!(matches!(m.validate(), Err(ModelError::Field { joint: 2, field: "limits", .. })));
        let mut m = irb120();
        m.links[0].d = f64::NAN;
        assert!(matches!(m.validate(), Err(ModelError::Field { joint: 0, field: "d", .. })));
        let mut m = irb120();
        m.links.clear();
        assert_eq!(m.validate(), Err(ModelError::JointCount(0)));
    }
}

//! `urdf`: the calibrated kinematic chain as a URDF — geometry only. Links `world` ({W}, the
//! measurement frame), `base_link` ({0}), `link_1` … `link_n` (the modified-DH frames {i}) and
//! `tool0` (the TCP {T}); the base and the tool are fixed joints, each robot joint a revolute
//! joint about its z axis whose origin is the whole calibrated MDH/Hayati row at q = 0:
//! `Rx(α_{i−1}) · Tx(a_{i−1}) · Ry(β_{i−1}) · Rz(θ offset_i) · Tz(d_i)` (Tz(d_i) commutes with the
//! joint's Rz(q_i), so the child frame is exactly {i}). URDF joint positions are the controller's
//! joint readings q (rad).
//!
//! Gear compliance under gravity, and any effect term (cyclic, backlash, thermal, …), cannot be
//! expressed in URDF: a URDF forward kinematics equals robocal's with those off, and differs from
//! the full model by the compliance deflection. The file says so in a comment. Numbers are written
//! in Rust's shortest round-trip form, so the file holds the model's doubles exactly.

use nalgebra::{Matrix3, Vector3};

use super::{ExportSource, exact};
use crate::domain::ParameterSetDoc;
use crate::kinematics::ParameterSet;
use crate::kinematics::frame::{Frame, rot_x, rot_y, rot_z};
use crate::kinematics::params::{JointTerm, Param};

/// URDF's `rpy` (roll, pitch, yaw) of a rotation, `R = Rz(yaw) · Ry(pitch) · Rx(roll)`.
///
/// Yaw from the first column, then pitch and roll from `Rz(yaw)ᵀ · R = Ry(pitch) · Rx(roll)`: the
/// roll absorbs whatever the yaw's rounding left, so the composition reproduces R to rounding even
/// at (or near) gimbal lock, where the textbook formulas lose digits as 1/cos(pitch) — an MDH row
/// with α = −90° and θ offset −90° (the IRB 120's joint 2) is exactly there.
pub fn rpy(r: &Matrix3<f64>) -> [f64; 3] {
    let yaw = r[(1, 0)].atan2(r[(0, 0)]);
    let (s, c) = yaw.sin_cos();
    let pitch = (-r[(2, 0)]).atan2(c * r[(0, 0)] + s * r[(1, 0)]);
    let roll = (s * r[(0, 2)] - c * r[(1, 2)]).atan2(c * r[(1, 1)] - s * r[(0, 1)]);
    [roll, pitch, yaw]
}

/// The origin of joint j (0-based) in link frame {j}: the calibrated MDH/Hayati row at q = 0.
pub fn joint_origin(set: &ParameterSet, j: usize) -> Frame {
    let l = &set.model.links[j];
    let v = |p: Param, default: f64| set.value(p).unwrap_or(default);
    let alpha = v(Param::Alpha(j), l.alpha);
    let a = v(Param::A(j), l.a);
    let theta = v(Param::Theta(j), l.theta);
    let d = v(Param::D(j), l.d);
    let beta = set.value(Param::Beta(j)).or(l.beta);
    let mut f = Frame::new(rot_x(alpha), Vector3::new(a, 0.0, 0.0));
    if let Some(b) = beta {
        f = f.compose(&Frame::new(rot_y(b), Vector3::zeros()));
    }
    f.compose(&Frame::new(rot_z(theta), Vector3::zeros()))
        .compose(&Frame::new(Matrix3::identity(), Vector3::new(0.0, 0.0, d)))
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;").replace('\'', "&apos;")
}

/// Text safe inside an XML comment (no `--`).
fn comment(s: &str) -> String {
    let mut t = s.replace("--", "- -");
    while t.contains("--") {
        t = t.replace("--", "- -");
    }
    t
}

fn origin(f: &Frame) -> String {
    let [r, p, y] = rpy(&f.r);
    format!(
        "<origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
        exact(f.t.x),
        exact(f.t.y),
        exact(f.t.z),
        exact(r),
        exact(p),
        exact(y)
    )
}

/// The URDF text of a parameter set.
pub fn write(doc: &ParameterSetDoc, source: &ExportSource) -> String {
    let set = &doc.set;
    let n = set.dof();
    let name = escape(&set.model.name);
    let mut x = String::from("<?xml version=\"1.0\"?>\n");
    x.push_str(&format!(
        "<!-- robocal calibrated kinematic model: robot {}, {}.\n",
        comment(&set.model.name),
        comment(&source.label)
    ));
    x.push_str(
        "     GEOMETRY ONLY. Each joint's origin is its calibrated modified-DH row (Craig) with Hayati's beta at\n     \
         q = 0: Rx(alpha_{i-1}) Tx(a_{i-1}) Ry(beta_{i-1}) Rz(theta_offset_i) Tz(d_i), about its z axis; joint\n     \
         positions are the controller's joint readings (rad). world is the measurement frame {W}, base_link the\n     \
         calibrated robot base {0}, tool0 the calibrated TCP. Gear compliance under gravity (the deflection\n     \
         c_i * tau_i of each joint) cannot be expressed in URDF: a URDF forward kinematics differs from\n     \
         robocal's by that deflection (tens of micrometres on an IRB 120). Lengths m, angles rad, written in\n     \
         shortest round-trip form (exact doubles). Joint effort and velocity limits are not known here (0).\n",
    );
    let left_out: Vec<String> = set
        .layout
        .params()
        .iter()
        .enumerate()
        .filter(|(_, p)| {
            !matches!(
                p,
                Param::Alpha(_)
                    | Param::A(_)
                    | Param::Theta(_)
                    | Param::D(_)
                    | Param::Beta(_)
                    | Param::Base(_)
                    | Param::Tool(_)
            )
        })
        .filter(|&(i, _)| set.values[i] != 0.0)
        .map(|(i, p)| {
            let k = p.unit().to_si();
            let what = if matches!(p, Param::Joint(_, JointTerm::Compliance)) { "compliance" } else { "effect term" };
            format!("{p} = {} {} ({what})", exact(set.values[i] / k), p.unit().as_str())
        })
        .collect();
    if !left_out.is_empty() {
        x.push_str(&format!("     Not expressed here: {}.\n", comment(&left_out.join("; "))));
    }
    x.push_str("-->\n");
    x.push_str(&format!("<robot name=\"{name}\">\n"));
    x.push_str("  <link name=\"world\"/>\n  <link name=\"base_link\"/>\n");
    for j in 1..=n {
        x.push_str(&format!("  <link name=\"link_{j}\"/>\n"));
    }
    x.push_str("  <link name=\"tool0\"/>\n");
    let base = Frame::from_xyzabc(&set.pose_of(Param::Base));
    x.push_str(&format!(
        "  <joint name=\"base\" type=\"fixed\">\n    <parent link=\"world\"/>\n    <child link=\"base_link\"/>\n    {}\n  </joint>\n",
        origin(&base)
    ));
    for j in 0..n {
        let parent = if j == 0 { "base_link".to_string() } else { format!("link_{j}") };
        let [lo, hi] = set.model.links[j].limits;
        x.push_str(&format!(
            "  <joint name=\"joint_{}\" type=\"revolute\">\n    <parent link=\"{parent}\"/>\n    <child link=\"link_{}\"/>\n    \
             {}\n    <axis xyz=\"0 0 1\"/>\n    <limit lower=\"{}\" upper=\"{}\" effort=\"0\" velocity=\"0\"/>\n  </joint>\n",
            j + 1,
            j + 1,
            origin(&joint_origin(set, j)),
            exact(lo),
            exact(hi)
        ));
    }
    let tool = Frame::from_xyzabc(&set.pose_of(Param::Tool));
    x.push_str(&format!(
        "  <joint name=\"tool\" type=\"fixed\">\n    <parent link=\"link_{n}\"/>\n    <child link=\"tool0\"/>\n    {}\n  </joint>\n",
        origin(&tool)
    ));
    x.push_str("</robot>\n");
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::thesis::{irb120_table_5_1, trical_tool};
    use crate::kinematics::{JointState, Tool};
    use nalgebra::{Matrix4, Rotation3, Unit};
    use rand::{Rng, SeedableRng};

    fn matrix(xyz: [f64; 3], rpy: [f64; 3]) -> Matrix4<f64> {
        // URDF: T = Trans(xyz) · Rz(yaw) · Ry(pitch) · Rx(roll).
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), rpy[2])
            * Rotation3::from_axis_angle(&Vector3::y_axis(), rpy[1])
            * Rotation3::from_axis_angle(&Vector3::x_axis(), rpy[0]);
        let mut m = r.to_homogeneous();
        m[(0, 3)] = xyz[0];
        m[(1, 3)] = xyz[1];
        m[(2, 3)] = xyz[2];
        m
    }

    /// Forward kinematics of a parsed URDF: from `world` down the chain to `tool0`, each joint's
    /// `Trans(xyz)·RPY(rpy)` then its rotation about `axis` by q (revolute joints in order).
    fn urdf_fk(robot: &urdf_rs::Robot, q: &[f64]) -> Matrix4<f64> {
        let mut t = Matrix4::identity();
        let mut link = "world".to_string();
        let mut k = 0;
        while link != "tool0" {
            let j = robot.joints.iter().find(|j| j.parent.link == link).expect("a joint out of every link but tool0");
            t *= matrix(*j.origin.xyz, *j.origin.rpy);
            if j.joint_type == urdf_rs::JointType::Revolute {
                let axis = Unit::new_normalize(Vector3::from(*j.axis.xyz));
                t *= Rotation3::from_axis_angle(&axis, q[k]).to_homogeneous();
                k += 1;
            }
            link = j.child.link.clone();
        }
        assert_eq!(k, q.len());
        t
    }

    fn check(set: ParameterSet, seed: u64) {
        let doc = ParameterSetDoc::new(set.clone());
        let text = write(&doc, &ExportSource::stored("s-1", 2));
        let robot = urdf_rs::read_from_string(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(robot.name, set.model.name);
        assert_eq!(robot.joints.len(), set.dof() + 2);
        let chain = set.chain();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut worst = 0.0f64;
        for _ in 0..2000 {
            let q: Vec<f64> = set.model.links.iter().map(|l| rng.random_range(l.limits[0]..l.limits[1])).collect();
            let u = urdf_fk(&robot, &q);
            // robocal's geometric FK: no torques, so no compliance deflection.
            let f = chain.fk(&JointState::new(&q));
            let dp = (Vector3::new(u[(0, 3)], u[(1, 3)], u[(2, 3)]) - f.t).norm();
            let dr = (u.fixed_view::<3, 3>(0, 0) - f.r).abs().max();
            worst = worst.max(dp);
            assert!(dp < 1e-12, "position differs by {dp} m at {q:?}"); // 1e-9 mm
            assert!(dr < 1e-14, "rotation differs by {dr} at {q:?}");
        }
        eprintln!("{}: worst URDF-vs-robocal TCP difference {worst:e} m", set.model.name);
    }

    /// The URDF read back by an independent parser (urdf-rs) gives robocal's geometric forward
    /// kinematics to 1e-9 mm at random configurations: the calibrated IRB 120 (Table 5.1, with β
    /// and a tool), the nominal IRB 120 (rows exactly at gimbal lock) and a perturbed UR10 (two β).
    #[test]
    fn parsed_back_it_gives_robocals_geometric_fk() {
        check(irb120_table_5_1(trical_tool()), 1);
        check(ParameterSet::nominal(crate::kinematics::model::irb120(), Tool::flange(), [0.0; 6]), 2);
        let mut ur = ParameterSet::nominal(
            crate::kinematics::model::ur10(),
            Tool { tcp: [0.01, -0.02, 0.15, 0.3, -1.2, 2.9], mass: 1.0, com: Vector3::zeros() },
            [1.2, -0.4, 0.1, 3.0, std::f64::consts::FRAC_PI_2, -0.2],
        );
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for i in 0..ur.values.len() {
            if !matches!(ur.layout.params()[i], Param::Joint(..)) {
                ur.values[i] += rng.random_range(-1e-3..1e-3);
            }
        }
        check(ur, 3);
    }

    #[test]
    fn rpy_reproduces_rotations_at_gimbal_lock() {
        let h = std::f64::consts::FRAC_PI_2;
        for (a, b, c) in [(0.3, h, -1.0), (0.3, -h, 2.0), (-h, h, 0.0), (1.0, 0.2, -0.4), (3.0, h - 1e-9, 0.5)] {
            let r = rot_z(a) * rot_y(b) * rot_x(c);
            let [roll, pitch, yaw] = rpy(&r);
            let back = rot_z(yaw) * rot_y(pitch) * rot_x(roll);
            assert!((back - r).abs().max() < 1e-15, "{a} {b} {c}");
        }
    }

    /// The file says it is geometry only, and the compliance it leaves out is real: with the
    /// gravity torques, robocal's TCP moves away from the URDF's.
    #[test]
    fn it_says_what_it_leaves_out() {
        let set = irb120_table_5_1(trical_tool());
        let text = write(&ParameterSetDoc::new(set.clone()), &ExportSource::file("params.json"));
        assert!(text.contains("GEOMETRY ONLY") && text.contains("compliance"));
        assert!(text.contains("c5 = -0.03044"), "{text}");
        let q = [0.3, 0.4, -0.2, 0.5, 0.9, 0.1];
        let geometric = set.chain().fk(&JointState::new(&q));
        let full = set.fk(&q);
        assert!((full.t - geometric.t).norm() > 1e-6);
        let e = "a--b".to_string();
        assert!(!comment(&e).contains("--"));
    }
}

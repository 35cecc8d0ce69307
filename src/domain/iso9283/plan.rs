//! The ISO 9283 test cube planned for a robot (clause 6.2.1 and figure 2 of the standard), and a
//! program that visits its poses in the standard's cycle order (P1 → P2 → P3 → P4 → P5, n cycles).
//!
//! - **The cube**: edges parallel to the base axes, every TCP pose with one orientation (given;
//!   default the flange's z axis pointing down), searched over centres on a grid in the x–z half-
//!   plane in front of the robot (y = 0) and, per centre, the largest edge by bisection such that the
//!   nominal model's numerical IK reaches the centre and the 8 corners **on one branch**: each corner
//!   is solved from the centre's solution (converged to 1 nm / 1 µrad), within the joint limits,
//!   with no joint more than 90° from the centre's solution and joint 5 (the wrist) of the same sign
//!   — a corner reachable only by flipping the wrist, or by a turn of a joint, is not on the branch.
//!   Bisection takes the feasible edges as an interval; where they are not (a hole in the
//!   envelope) the edge found is feasible, not necessarily the largest.
//! - **The poses**: the diagonal plane through the corners (xmin, ymin, ·) and (xmax, ymax, ·);
//!   P1 is the centre; P2 … P5 lie on that plane's diagonals at 10 % of the diagonal's length from
//!   the corners: P2 near (xmin, ymin, zmax), P3 near (xmax, ymax, zmax), P4 near (xmax, ymax,
//!   zmin), P5 near (xmin, ymin, zmin).
//! - **The programs**: RAPID and URScript, Cartesian targets of the flange (tool0 / the UR's
//!   flange) in the base frame, in mm and quaternions (RAPID, with confdata from the joint
//!   quadrants; cfx from the closed form where the robot has one) or m and rotation vectors
//!   (URScript). KRL and Fanuc TP are not written.
//! - **Not checked**: collisions. The envelope is the IK's reach within the joint limits; the
//!   plan knows no floor, table, fixture or the robot's own links. Look at the cube before running
//!   it (a cube reaching below the base plane is common for a floor-mounted arm: give another
//!   orientation, or move the cube).

use nalgebra::{Matrix3, Vector3};

use crate::kinematics::frame::{quaternion_from_rot, rotation_vector};
use crate::kinematics::ik_analytic::quadrant;
use crate::kinematics::ik_numeric::solve;
use crate::kinematics::{AnalyticIk, Frame, IkOptions, ParameterSet};

/// A planned test cube.
#[derive(Clone, Debug, PartialEq)]
pub struct CubePlan {
    /// Centre, m, base frame.
    pub centre: Vector3<f64>,
    /// Edge length, m.
    pub edge: f64,
    /// The TCP orientation of every pose.
    pub orientation: Matrix3<f64>,
    /// The centre then the 8 corners, with the joints the IK found (rad).
    pub cube: Vec<(Vector3<f64>, Vec<f64>)>,
    /// P1 … P5 and their joints (rad).
    pub poses: Vec<(Frame, Vec<f64>)>,
}

/// Why no cube was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error("the robot has {0} joints: the cube search needs 6")]
    Joints(usize),
    #[error("no centre of the search grid is reachable with this orientation on one branch")]
    NoCube,
}

/// The cube's corners: index bits (x, y, z) = (k & 1, k & 2, k & 4), low = min.
pub fn corners(centre: &Vector3<f64>, edge: f64) -> [Vector3<f64>; 8] {
    let h = edge / 2.0;
    std::array::from_fn(|k| {
        centre
            + Vector3::new(
                if k & 1 == 0 { -h } else { h },
                if k & 2 == 0 { -h } else { h },
                if k & 4 == 0 { -h } else { h },
            )
    })
}

/// P1 … P5 positions of a cube (see the module documentation).
pub fn iso_points(centre: &Vector3<f64>, edge: f64) -> [Vector3<f64>; 5] {
    let c = corners(centre, edge);
    // Diagonal-plane corners: (xmin,ymin,zmax)=c[4], (xmax,ymax,zmax)=c[7], (xmax,ymax,zmin)=c[3],
    // (xmin,ymin,zmin)=c[0]; each diagonal runs to the opposite one.
    let near = |from: Vector3<f64>, to: Vector3<f64>| from + 0.1 * (to - from);
    [*centre, near(c[4], c[3]), near(c[7], c[0]), near(c[3], c[4]), near(c[0], c[7])]
}

/// A feasible cube: (edge, centre, the centre's joints, the corners' joints).
type Candidate = (f64, Vector3<f64>, Vec<f64>, Vec<Vec<f64>>);

struct Reach<'a> {
    set: &'a ParameterSet,
    orientation: Matrix3<f64>,
    opts: IkOptions,
}

impl Reach<'_> {
    fn solve(&self, p: &Vector3<f64>, seed: &[f64]) -> Option<Vec<f64>> {
        let chain = self.set.chain();
        let gravity = self.set.gravity();
        let target = Frame::new(self.orientation, *p);
        let s = solve(&chain, &gravity, &target, seed, &self.opts).ok()?;
        let q = s.joints().to_vec();
        let ok = s.residual_position <= 1e-9
            && s.residual_rotation <= 1e-6
            && q.iter().enumerate().all(|(j, &v)| self.set.model.within_limits(j, v));
        ok.then_some(q)
    }

    /// The corners' joints when all 8 are on the centre's branch.
    fn cube(&self, centre: &Vector3<f64>, q0: &[f64], edge: f64) -> Option<Vec<Vec<f64>>> {
        corners(centre, edge)
            .iter()
            .map(|p| {
                let q = self.solve(p, q0)?;
                let same =
                    q.iter().zip(q0).all(|(a, b)| (a - b).abs() < std::f64::consts::FRAC_PI_2) && (q[4] * q0[4] > 0.0);
                same.then_some(q)
            })
            .collect()
    }
}

/// Plan the largest cube (module documentation) for `set`'s nominal geometry with its tool, the
/// TCP turned `orientation` in the base frame, starting the IK from `seed` (rad), over a grid of
/// `grid` × `grid` centres.
pub fn plan_cube(
    set: &ParameterSet,
    orientation: Matrix3<f64>,
    seed: &[f64],
    grid: usize,
) -> Result<CubePlan, PlanError> {
    if set.dof() != 6 {
        return Err(PlanError::Joints(set.dof()));
    }
    let reach = Reach { set, orientation, opts: IkOptions::default() };
    // A length scale of the arm: the sum of its link lengths and offsets.
    let r: f64 = set.model.links.iter().map(|l| l.a.abs() + l.d.abs()).sum();
    let base = set.chain().base().t;
    // (edge, centre, the centre's joints, the corners' joints)
    let mut best: Option<Candidate> = None;
    let n = grid.max(2);
    for i in 0..n {
        for k in 0..n {
            let x = r * (0.25 + 0.5 * i as f64 / (n - 1) as f64);
            let z = r * (-0.1 + 0.6 * k as f64 / (n - 1) as f64);
            let centre = base + Vector3::new(x, 0.0, z);
            let Some(q0) = reach.solve(&centre, seed) else { continue };
            if q0[4].abs() < 1e-3 {
                continue; // on the wrist singularity: no branch to keep
            }
            let (mut lo, mut hi) = (0.0, r);
            let mut found = None;
            for _ in 0..14 {
                let mid = 0.5 * (lo + hi);
                match reach.cube(&centre, &q0, mid) {
                    Some(c) => {
                        lo = mid;
                        found = Some(c);
                    }
                    None => hi = mid,
                }
            }
            if let Some(c) = found
                && best.as_ref().is_none_or(|b| lo > b.0)
            {
                best = Some((lo, centre, q0, c));
            }
        }
    }
    let (edge, centre, q0, qs) = best.ok_or(PlanError::NoCube)?;
    let mut cube = vec![(centre, q0.clone())];
    cube.extend(corners(&centre, edge).into_iter().zip(qs));
    let poses = iso_points(&centre, edge)
        .iter()
        .map(|p| {
            // Inside the cube on the centre's branch (the cube is convex in the joints' reach only
            // approximately: solved and checked like the corners).
            let q = reach.solve(p, &q0).ok_or(PlanError::NoCube)?;
            Ok((Frame::new(orientation, *p), q))
        })
        .collect::<Result<Vec<_>, PlanError>>()?;
    Ok(CubePlan { centre, edge, orientation, cube, poses })
}

/// A controller language the plan is written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlanLanguage {
    Rapid,
    Urscript,
}

impl PlanLanguage {
    pub fn parse(s: &str) -> Option<PlanLanguage> {
        match s.to_ascii_lowercase().as_str() {
            "rapid" => Some(PlanLanguage::Rapid),
            "urscript" => Some(PlanLanguage::Urscript),
            _ => None,
        }
    }
}

/// The program visiting P1 … P5 for `cycles` cycles.
pub fn write_program(plan: &CubePlan, set: &ParameterSet, language: PlanLanguage, cycles: u32) -> String {
    let head = format!(
        "ISO 9283 test cube: centre {:.3}, {:.3}, {:.3} mm, edge {:.3} mm; P1 centre, P2-P5 at 10 % of the diagonal from the corners",
        plan.centre.x * 1e3,
        plan.centre.y * 1e3,
        plan.centre.z * 1e3,
        plan.edge * 1e3
    );
    match language {
        PlanLanguage::Rapid => {
            let ik = AnalyticIk::new(&set.model, set.chain().base(), set.chain().tool()).ok();
            let mut s = format!("MODULE ISO9283\n  ! {head}\n");
            for (k, (f, q)) in plan.poses.iter().enumerate() {
                let qt = quaternion_from_rot(&f.r);
                let cfx = ik.as_ref().map_or(0, |ik| ik.confdata(q).cfx.cfx());
                s.push_str(&format!(
                    "  CONST robtarget P{}:=[[{:.4},{:.4},{:.4}],[{:.9},{:.9},{:.9},{:.9}],[{},{},{},{}],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];\n",
                    k + 1,
                    f.t.x * 1e3,
                    f.t.y * 1e3,
                    f.t.z * 1e3,
                    qt[0],
                    qt[1],
                    qt[2],
                    qt[3],
                    quadrant(q[0]),
                    quadrant(q[3]),
                    quadrant(q[5]),
                    cfx
                ));
            }
            s.push_str(&format!("  PROC main()\n    FOR i FROM 1 TO {cycles} DO\n"));
            for k in 1..=5 {
                s.push_str(&format!("      MoveL P{k}, v500, fine, tool0;\n      WaitTime 3;\n"));
            }
            s.push_str("    ENDFOR\n  ENDPROC\nENDMODULE\n");
            s
        }
        PlanLanguage::Urscript => {
            let mut s = format!("def iso9283():\n  # {head}\n");
            for (k, (f, _)) in plan.poses.iter().enumerate() {
                let v = rotation_vector(&f.r);
                s.push_str(&format!(
                    "  P{} = p[{:.7}, {:.7}, {:.7}, {:.9}, {:.9}, {:.9}]\n",
                    k + 1,
                    f.t.x,
                    f.t.y,
                    f.t.z,
                    v.x,
                    v.y,
                    v.z
                ));
            }
            s.push_str(&format!("  i = 0\n  while i < {cycles}:\n"));
            for k in 1..=5 {
                s.push_str(&format!("    movel(P{k}, a=0.5, v=0.25)\n    sleep(3.0)\n"));
            }
            s.push_str("    i = i + 1\n  end\nend\n");
            s
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact geometry: P2 … P5 lie in the diagonal plane, at 10 % of the diagonal from their
    /// corners, P1 at the centre; P2–P4 and P3–P5 are 80 % of a diagonal apart.
    #[test]
    fn the_iso_points_sit_where_the_standard_puts_them() {
        let c = Vector3::new(0.4, -0.1, 0.5);
        let e = 0.3;
        let p = iso_points(&c, e);
        let k = corners(&c, e);
        let diagonal = (e * e * 2.0 + e * e).sqrt(); // of the diagonal plane: √(2e² + e²)
        assert_eq!(p[0], c);
        for (pt, corner) in [(p[1], k[4]), (p[2], k[7]), (p[3], k[3]), (p[4], k[0])] {
            assert!(((pt - corner).norm() - 0.1 * diagonal).abs() < 1e-15);
            // In the plane through (xmin,ymin) and (xmax,ymax): x − cx = y − cy.
            assert!(((pt.x - c.x) - (pt.y - c.y)).abs() < 1e-15);
        }
        assert!(((p[1] - p[3]).norm() - 0.8 * diagonal).abs() < 1e-15);
    }
}

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
//! - **The programs** ([`write_program`]): RAPID, KRL (`.src` + `.dat`), Fanuc TP (`.ls`) and
//!   URScript, Cartesian targets of the flange in the base frame: mm and quaternions (RAPID, with
//!   confdata from the joint quadrants; cfx from the closed form where the robot has one), mm and
//!   A, B, C deg ZY'X'' with S and T (KRL), mm and W, P, R deg with CONFIG (Fanuc), m and rotation
//!   vectors (URScript). Every cycle is written out. KRL and Fanuc need the closed form to label
//!   the branch (S/T, CONFIG) and are refused for a robot without one.
//! - **Not checked**: collisions. The envelope is the IK's reach within the joint limits; the
//!   plan knows no floor, table, fixture or the robot's own links. Look at the cube before running
//!   it (a cube reaching below the base plane is common for a floor-mounted arm: give another
//!   orientation, or move the cube).

use nalgebra::{Matrix3, Vector3};

use crate::domain::program::ProgramFile;
use crate::kinematics::frame::{quaternion_from_rot, rotation_vector, zyx_from_rot};
use crate::kinematics::ik_analytic::{Branch, quadrant};
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
    Krl,
    Fanuc,
    Urscript,
}

impl PlanLanguage {
    pub const ALL: [PlanLanguage; 4] =
        [PlanLanguage::Rapid, PlanLanguage::Krl, PlanLanguage::Fanuc, PlanLanguage::Urscript];

    pub fn parse(s: &str) -> Option<PlanLanguage> {
        match s.to_ascii_lowercase().as_str() {
            "rapid" => Some(PlanLanguage::Rapid),
            "krl" => Some(PlanLanguage::Krl),
            "fanuc" => Some(PlanLanguage::Fanuc),
            "urscript" => Some(PlanLanguage::Urscript),
            _ => None,
        }
    }

    /// The extension of the program's (first) file: `mod`, `src` (KRL also writes the `.dat`),
    /// `ls`, `script`.
    pub fn extension(self) -> &'static str {
        match self {
            PlanLanguage::Rapid => "mod",
            PlanLanguage::Krl => "src",
            PlanLanguage::Fanuc => "ls",
            PlanLanguage::Urscript => "script",
        }
    }
}

/// The most cycles a plan writes: the standard asks for 30; every cycle is written out (see
/// [`write_program`]), so this bounds the program's length (5 motions and 5 waits a cycle).
pub const MAX_CYCLES: u32 = 1000;

/// Whether `name` can name the program on every controller: a letter, then letters, digits or
/// `_`, at most 24 characters (KRL's and Fanuc's limits are the tightest).
pub fn valid_program_name(name: &str) -> bool {
    let b = name.as_bytes();
    !b.is_empty()
        && b.len() <= 24
        && b[0].is_ascii_alphabetic()
        && b.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

/// Why a program is not written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WriteError {
    #[error("'{0}' cannot name a program: a letter, then letters, digits or '_', at most 24 characters")]
    Name(String),
    #[error("cycles must be between 1 and {MAX_CYCLES}, not {0}")]
    Cycles(u32),
    /// KRL's S/T and Fanuc's CONFIG label the branches of a spherical-wrist arm (the closed form
    /// of `kinematics::ik_analytic`); a robot without it has no such label to write.
    #[error(
        "{0} needs the configuration (KRL S and T, Fanuc CONFIG) of the planned joints, and this robot has no \
         closed-form IK to label it ({1}): write rapid or urscript"
    )]
    NoConfiguration(&'static str, String),
}

/// Whether `language` can be written for `set`'s robot (KRL and Fanuc need the closed form): a
/// check to make before planning.
pub fn check_language(set: &ParameterSet, language: PlanLanguage) -> Result<(), WriteError> {
    let name = match language {
        PlanLanguage::Krl => "krl",
        PlanLanguage::Fanuc => "fanuc",
        PlanLanguage::Rapid | PlanLanguage::Urscript => return Ok(()),
    };
    AnalyticIk::new(&set.model, set.chain().base(), set.chain().tool())
        .map(|_| ())
        .map_err(|e| WriteError::NoConfiguration(name, e.to_string()))
}

/// The branch labels of the planned poses, from the nominal model's closed form.
fn branches(plan: &CubePlan, set: &ParameterSet, language: &'static str) -> Result<Vec<Branch>, WriteError> {
    let ik = AnalyticIk::new(&set.model, set.chain().base(), set.chain().tool())
        .map_err(|e| WriteError::NoConfiguration(language, e.to_string()))?;
    Ok(plan.poses.iter().map(|(_, q)| ik.classify(q)).collect())
}

/// Fanuc's turn number of a joint: n with q in [−180° + n·360°, 180° + n·360°).
fn fanuc_turn(q: f64) -> i64 {
    ((q + std::f64::consts::PI) / std::f64::consts::TAU).floor() as i64
}

/// The program visiting P1 … P5 for `cycles` cycles, named `name`, as its files (KRL: the `.src`
/// then the `.dat`). Every cycle is written out, P1 → P5 with a 3 s wait at each pose for the
/// reading, so the motions are the standard's cycle order as a program reader sees them (and
/// Fanuc TP needs no register for a loop counter). The flange (RAPID `tool0`, KRL `$TOOL =
/// $NULLFRAME`, Fanuc `UT : 0`, URScript `set_tcp(p[0,0,0,0,0,0])`) in the robot's base frame
/// (`wobj0`, `$BASE = $NULLFRAME`, `UF : 0`); the first motion is a joint move onto P1, the others
/// linear. Numbers: positions to 0.1 µm (URScript 0.1 µm in metres), angles to 1e-7°
/// (quaternions and rotation vectors to 1e-9), finer than a controller's 32-bit REAL keeps; KRL
/// S and T and Fanuc CONFIG are the planned joints' (the closed form's branch labels).
pub fn write_program(
    plan: &CubePlan,
    set: &ParameterSet,
    language: PlanLanguage,
    cycles: u32,
    name: &str,
) -> Result<Vec<ProgramFile>, WriteError> {
    if !valid_program_name(name) {
        return Err(WriteError::Name(name.to_string()));
    }
    if !(1..=MAX_CYCLES).contains(&cycles) {
        return Err(WriteError::Cycles(cycles));
    }
    let head = format!(
        "ISO 9283 test cube: centre {:.3}, {:.3}, {:.3} mm, edge {:.3} mm; P1 centre, P2-P5 at 10 % of the diagonal from the corners",
        plan.centre.x * 1e3,
        plan.centre.y * 1e3,
        plan.centre.z * 1e3,
        plan.edge * 1e3
    );
    let file = |ext: &str, text: String| ProgramFile { name: format!("{name}.{ext}"), bytes: text.into_bytes() };
    let mm = |f: &Frame| [f.t.x * 1e3, f.t.y * 1e3, f.t.z * 1e3];
    let abc = |f: &Frame| zyx_from_rot(&f.r).map(|v| v.to_degrees());
    Ok(match language {
        PlanLanguage::Rapid => {
            let ik = AnalyticIk::new(&set.model, set.chain().base(), set.chain().tool()).ok();
            let mut s = format!("MODULE {name}\n  ! {head}\n");
            for (k, (f, q)) in plan.poses.iter().enumerate() {
                let qt = quaternion_from_rot(&f.r);
                let cfx = ik.as_ref().map_or(0, |ik| ik.confdata(q).cfx.cfx());
                let p = mm(f);
                s.push_str(&format!(
                    "  CONST robtarget P{}:=[[{:.4},{:.4},{:.4}],[{:.9},{:.9},{:.9},{:.9}],[{},{},{},{}],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];\n",
                    k + 1,
                    p[0],
                    p[1],
                    p[2],
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
            s.push_str("  PROC main()\n");
            for c in 1..=cycles {
                s.push_str(&format!("    ! cycle {c}\n"));
                for k in 1..=5 {
                    let mv = if c == 1 && k == 1 { "MoveJ" } else { "MoveL" };
                    s.push_str(&format!("    {mv} P{k}, v500, fine, tool0;\n    WaitTime 3;\n"));
                }
            }
            s.push_str("  ENDPROC\nENDMODULE\n");
            vec![file("mod", s)]
        }
        PlanLanguage::Krl => {
            let b = branches(plan, set, "krl")?;
            let mut src = format!(
                "&ACCESS RVP\n&REL 1\nDEF {name}( )\n; {head}\n; The flange ($TOOL = $NULLFRAME) in the robot's base frame ($BASE = $NULLFRAME, $ROBROOT the world); the points are in {name}.dat\nBAS (#INITMOV,0 )\nBAS (#VEL_PTP,20 )\n$TOOL = $NULLFRAME\n$BASE = $NULLFRAME\n$VEL.CP = 0.5\n"
            );
            for c in 1..=cycles {
                src.push_str(&format!("; cycle {c}\n"));
                for k in 1..=5 {
                    let mv = if c == 1 && k == 1 { "PTP" } else { "LIN" };
                    src.push_str(&format!("{mv} XP{k}\nWAIT SEC 3\n"));
                }
            }
            src.push_str("END\n");
            let mut dat = format!(
                "&ACCESS RVP\n&REL 1\nDEFDAT  {name}\n; {head}\n; X, Y, Z mm and A, B, C deg (ZY'X'') of the flange in the robot's base frame; S and T of the planned joints\n"
            );
            for (k, ((f, q), br)) in plan.poses.iter().zip(&b).enumerate() {
                let p = mm(f);
                let a = abc(f);
                let s = u32::from(br.shoulder_back())
                    | u32::from(br.elbow_behind()) << 1
                    | u32::from(br.wrist_negative()) << 2;
                let t = q.iter().take(6).enumerate().fold(0u32, |t, (j, v)| if *v < 0.0 { t | 1 << j } else { t });
                dat.push_str(&format!(
                    "DECL E6POS XP{}={{X {:.4},Y {:.4},Z {:.4},A {:.7},B {:.7},C {:.7},S {s},T {t},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}\n",
                    k + 1,
                    p[0],
                    p[1],
                    p[2],
                    a[0],
                    a[1],
                    a[2]
                ));
            }
            dat.push_str("ENDDAT\n");
            vec![file("src", src), file("dat", dat)]
        }
        PlanLanguage::Fanuc => {
            let b = branches(plan, set, "fanuc")?;
            let mut mn: Vec<String> = vec!["  UFRAME_NUM=0 ;".into(), "  UTOOL_NUM=0 ;".into()];
            for c in 1..=cycles {
                mn.push(format!("  !ISO 9283 cycle {c} ;"));
                for k in 1..=5 {
                    mn.push(if c == 1 && k == 1 {
                        format!("J P[{k}] 20% FINE    ;")
                    } else {
                        format!("L P[{k}] 500mm/sec FINE    ;")
                    });
                    mn.push("  WAIT   3.00(sec) ;".into());
                }
            }
            let mut s = format!(
                "/PROG  {name}\n/ATTR\nOWNER\t\t= MNEDITOR;\nCOMMENT\t\t= \"ISO 9283 cube\";\nPROG_SIZE\t= 0;\nFILE_NAME\t= ;\nVERSION\t\t= 0;\nLINE_COUNT\t= {};\nMEMORY_SIZE\t= 0;\nPROTECT\t\t= READ_WRITE;\nTCD:  STACK_SIZE\t= 0,\n      TASK_PRIORITY\t= 50,\n      TIME_SLICE\t= 0,\n      BUSY_LAMP_OFF\t= 0,\n      ABORT_REQUEST\t= 0,\n      PAUSE_REQUEST\t= 0;\nDEFAULT_GROUP\t= 1,*,*,*,*;\nCONTROL_CODE\t= 00000000 00000000;\n/MN\n",
                mn.len()
            );
            for (i, l) in mn.iter().enumerate() {
                s.push_str(&format!("{:>4}:{l}\n", i + 1));
            }
            s.push_str("/POS\n");
            for (k, ((f, q), br)) in plan.poses.iter().zip(&b).enumerate() {
                let p = mm(f);
                let a = abc(f);
                s.push_str(&format!(
                    "P[{}]{{\n   GP1:\n\tUF : 0, UT : 0,\t\tCONFIG : '{} {} {}, {}, {}, {}',\n\tX = {:>12.4}  mm,\tY = {:>12.4}  mm,\tZ = {:>12.4}  mm,\n\tW = {:>12.7} deg,\tP = {:>12.7} deg,\tR = {:>12.7} deg\n}};\n",
                    k + 1,
                    if br.wrist_negative() { 'F' } else { 'N' },
                    if br.elbow_behind() { 'D' } else { 'U' },
                    if br.shoulder_back() { 'B' } else { 'T' },
                    fanuc_turn(q[3]),
                    fanuc_turn(q[4]),
                    fanuc_turn(q[5]),
                    p[0],
                    p[1],
                    p[2],
                    a[2],
                    a[1],
                    a[0]
                ));
            }
            s.push_str("/END\n");
            vec![file("ls", s)]
        }
        PlanLanguage::Urscript => {
            let mut s = format!("def {name}():\n  # {head}\n  set_tcp(p[0, 0, 0, 0, 0, 0])\n");
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
            for c in 1..=cycles {
                s.push_str(&format!("  # cycle {c}\n"));
                for k in 1..=5 {
                    let mv = if c == 1 && k == 1 {
                        "movej(P1, a=0.5, v=0.5)".to_string()
                    } else {
                        format!("movel(P{k}, a=0.5, v=0.25)")
                    };
                    s.push_str(&format!("  {mv}\n  sleep(3.0)\n"));
                }
            }
            s.push_str("end\n");
            vec![file("script", s)]
        }
    })
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

//! Capsule collision model of the robot, its tool and the cell (used by [`super::poses`]).
//!
//! Every body is a capsule — the set of points within `radius` of a segment — so a test between
//! two parts reduces to an exact segment–segment distance, one against the table to the heights
//! of the segment's ends, and one against the plate to a golden-section search of the prism's
//! signed distance along the segment (the primitives are in `super::geometry` and re-exported
//! here). Robot parts are fixed in link frames and placed
//! by the chain's forward-kinematics [`Trace`], so they follow whatever parameter set the chain was
//! compiled at. The cell contributes two obstacles: the table (the robot's mounting plane, a
//! half-space) and the artefact's plate with its stand (a vertical prism).
//!
//! A configuration passes the static check when, each with its clearance margin:
//! - no two non-adjacent parts come closer than [`Clearances::parts`] (see
//!   [`CollisionModel::irb120`] for the pairs);
//! - every part except the base column stays [`Clearances::table`] above the table;
//! - no part comes within [`Clearances::plate`] of the plate prism.
//!
//! The checks report the first violation in that order (pairs in their listed order), with its
//! penetration depth. The balls and their rods are not modelled: the tool's contact zone holds a
//! ball when measuring, and everything else is kept off the plate they stand on (a link passing
//! through another ball's rod is therefore not caught).

use std::fmt;

use nalgebra::Vector3;

pub use super::geometry::{Capsule, HalfSpace, VerticalPrism, segment_distance};
use crate::kinematics::{Chain, JointState, Param, ParameterSet, Trace};
use crate::units::DEG;

/// A named body of the robot or its tool.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Part {
    /// Links 0 and 1: from the mounting plane up to axis 2.
    BaseColumn,
    /// Link 2: axis 2 to axis 3.
    UpperArm,
    /// Link 3's elbow: axis 3 along the a3 offset to axis 4.
    Elbow,
    /// Links 3–4 along axis 4 towards the wrist centre.
    Forearm,
    /// Link 5: wrist centre to the flange.
    Wrist,
    /// Capsule k of the tool body.
    Tool(usize),
    /// The tool's contact zone around the TCP (see [`ToolShape::contact`]).
    ToolContact,
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Part::BaseColumn => f.write_str("base column"),
            Part::UpperArm => f.write_str("upper arm"),
            Part::Elbow => f.write_str("elbow"),
            Part::Forearm => f.write_str("forearm"),
            Part::Wrist => f.write_str("wrist"),
            Part::Tool(0) => f.write_str("tool body"),
            Part::Tool(k) => write!(f, "tool body capsule {}", k + 1),
            Part::ToolContact => f.write_str("tool contact zone"),
        }
    }
}

/// What a part ran into.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Against {
    /// Another part of the robot or its tool.
    Part(Part),
    /// The table: the robot's mounting plane.
    Table,
    /// The artefact's plate and its stand.
    Plate,
}

impl fmt::Display for Against {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Against::Part(p) => p.fmt(f),
            Against::Table => f.write_str("table"),
            Against::Plate => f.write_str("artefact plate"),
        }
    }
}

/// A violated clearance. `penetration` is how deep the bodies overlap (m); it is negative when
/// they do not touch but are closer than the required `clearance` (m).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("{part} hits {against}: penetration {:.3} mm (clearance {:.1} mm required)", penetration * 1e3, clearance * 1e3)]
pub struct Collision {
    /// The part that violates the clearance (for a pair, the first of the pair).
    pub part: Part,
    /// What it comes too close to.
    pub against: Against,
    /// Overlap depth, m (negative: the gap is smaller than `clearance` but positive).
    pub penetration: f64,
    /// The clearance required, m.
    pub clearance: f64,
}

/// A joint-space move that collides on the way.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("move collides at sample {sample} of {samples} (q = {}): {collision}", fmt_deg(q))]
pub struct PathCollision {
    /// Index of the colliding sample, 0 = the start, `samples` = the end.
    pub sample: usize,
    /// Steps the move was cut into (its samples are 0 to `samples`).
    pub samples: usize,
    /// The colliding configuration, rad.
    pub q: Vec<f64>,
    /// The violation at that sample.
    pub collision: Collision,
}

fn fmt_deg(q: &[f64]) -> String {
    let v: Vec<String> = q.iter().map(|a| format!("{:.2}", a.to_degrees())).collect();
    format!("({})°", v.join(", "))
}

/// Safety margins (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clearances {
    /// Between non-adjacent parts.
    pub parts: f64,
    /// Above the table.
    pub table: f64,
    /// Off the artefact plate and stand.
    pub plate: f64,
}

impl Default for Clearances {
    /// 5 mm between parts and off the plate; 10 mm above the table (the table is the least
    /// precisely known surface of the cell: its height follows from the base guess).
    fn default() -> Self {
        Self { parts: 0.005, table: 0.010, plate: 0.005 }
    }
}

/// Capsule radii of the IRB 120's links (m), chosen to envelop the arm's castings as drawn in
/// the product specification (base 180 × 180 mm, arm castings roughly 100–120 mm across).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkRadii {
    /// Base column ([`Part::BaseColumn`]).
    pub base_column: f64,
    /// Upper arm ([`Part::UpperArm`]).
    pub upper_arm: f64,
    /// Forearm and elbow ([`Part::Forearm`], [`Part::Elbow`]).
    pub forearm: f64,
    /// Wrist ([`Part::Wrist`]).
    pub wrist: f64,
}

impl Default for LinkRadii {
    /// Base column 80 mm (160 mm across, inside the 180 mm footprint, housing the axis-2 motor),
    /// upper arm 60 mm, forearm and elbow 50 mm, wrist 40 mm.
    fn default() -> Self {
        Self { base_column: 0.080, upper_arm: 0.060, forearm: 0.050, wrist: 0.040 }
    }
}

/// A tool's collision shape in the flange frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolShape {
    /// The tool body.
    pub body: Vec<Capsule>,
    /// The zone around the TCP that closes on the measured ball. Checked like the body against
    /// the robot, the table and the plate; the ball and its rod, which it touches by design, are
    /// not modelled.
    pub contact: Option<Capsule>,
}

/// Frame a part is fixed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mount {
    /// The robot base {0}.
    Base,
    /// Link frame {j+1} (0-based joint j), as [`Trace::link_frame`].
    Link(usize),
    /// The flange frame {n}.
    Flange,
}

/// One part: a capsule fixed in a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PartShape {
    /// Which part.
    pub part: Part,
    /// The frame it is fixed in.
    pub mount: Mount,
    /// The capsule in that frame, m.
    pub local: Capsule,
}

/// The robot's parts, which pairs may not touch, and the cell's obstacles, at one parameter set.
#[derive(Clone, Debug, PartialEq)]
pub struct CollisionModel {
    chain: Chain,
    parts: Vec<PartShape>,
    pairs: Vec<(usize, usize)>,
    table: Option<HalfSpace>,
    plate: Option<VerticalPrism>,
    clearances: Clearances,
}

/// Largest joint step between path samples: 1°.
pub const PATH_STEP: f64 = DEG;

impl CollisionModel {
    /// A general model: `pairs` index into `parts`. The base column (if any) is exempt from the
    /// table check. Panics when a pair indexes outside `parts` or pairs a part with itself.
    pub fn new(
        chain: Chain,
        parts: Vec<PartShape>,
        pairs: Vec<(usize, usize)>,
        table: Option<HalfSpace>,
        plate: Option<VerticalPrism>,
        clearances: Clearances,
    ) -> Self {
        assert!(pairs.iter().all(|&(i, j)| i < parts.len() && j < parts.len() && i != j), "pairs index parts");
        Self { chain, parts, pairs, table, plate, clearances }
    }

    /// The IRB 120 (any ABB-family parameter set: the link lengths are read from `set`'s current
    /// values and the chain is `set.chain()`) with a tool body given in the flange frame. The
    /// table is the XY plane of the chain's base {0}; `plate` is the artefact's prism, if any.
    /// Panics when `set` lacks d1, a2, a3, d4 or d6.
    ///
    /// Parts, in the MDH link frames:
    /// - base column, in {0}: (0, 0, 0) → (0, 0, d1), from the mounting plane to axis 2;
    /// - upper arm, in {2}: (0, 0, 0) → (a2, 0, 0), axis 2 to axis 3;
    /// - elbow, in {3}: (0, 0, 0) → (a3, 0, 0), axis 3 to the foot of axis 4;
    /// - forearm, in {4}: (0, 0, −d4) → (0, 0, −r_forearm), along axis 4 to the wrist centre, cut
    ///   short by its radius so that its round end stops at the wrist centre: the wrist capsule
    ///   covers the wrist housing from there (a full-length forearm would always touch a tool body
    ///   wider than 22 mm on the flange, 72 mm from the wrist centre);
    /// - wrist, in {6}: (0, 0, −d6) → (0, 0, 0), wrist centre to flange;
    /// - the tool body's capsules and its contact zone, in {6}.
    ///
    /// Pairs checked (everything not sharing a joint or a rigid body): base column against
    /// elbow, forearm, wrist and tool; upper arm against wrist and tool; elbow against wrist and
    /// tool; forearm against tool ("tool": each body capsule and the contact zone). Left out as
    /// adjacent: base column–upper arm (axis 2), upper arm–elbow and upper arm–forearm (axis 3:
    /// the forearm axis is only 70 mm from it, less than the two radii, so they touch by
    /// construction; axis 3's limits keep them apart), elbow–forearm (one casting),
    /// forearm–wrist (axis 5), wrist–tool (the flange).
    pub fn irb120(
        set: &ParameterSet,
        radii: &LinkRadii,
        tool: &ToolShape,
        plate: Option<VerticalPrism>,
        clearances: Clearances,
    ) -> Self {
        let v = |p: Param| set.value(p).expect("an ABB-family model has this parameter");
        let (d1, a2, a3, d4, d6) = (v(Param::D(0)), v(Param::A(2)), v(Param::A(3)), v(Param::D(3)), v(Param::D(5)));
        let p = Vector3::new;
        let z0 = Vector3::zeros();
        let shape = |part, mount, a, b, radius| PartShape { part, mount, local: Capsule::new(a, b, radius) };
        let mut parts = vec![
            shape(Part::BaseColumn, Mount::Base, z0, p(0.0, 0.0, d1), radii.base_column),
            shape(Part::UpperArm, Mount::Link(1), z0, p(a2, 0.0, 0.0), radii.upper_arm),
            shape(Part::Elbow, Mount::Link(2), z0, p(a3, 0.0, 0.0), radii.forearm),
            shape(Part::Forearm, Mount::Link(3), p(0.0, 0.0, -d4), p(0.0, 0.0, -radii.forearm), radii.forearm),
            shape(Part::Wrist, Mount::Flange, p(0.0, 0.0, -d6), z0, radii.wrist),
        ];
        let (base, upper, elbow, forearm, wrist) = (0, 1, 2, 3, 4);
        let mut pairs = vec![(base, elbow), (base, forearm), (base, wrist), (upper, wrist), (elbow, wrist)];
        let tool_parts = tool.body.iter().enumerate().map(|(k, c)| (Part::Tool(k), c));
        for (part, c) in tool_parts.chain(tool.contact.iter().map(|c| (Part::ToolContact, c))) {
            let t = parts.len();
            parts.push(PartShape { part, mount: Mount::Flange, local: *c });
            pairs.extend([(base, t), (upper, t), (elbow, t), (forearm, t)]);
        }
        // Cheap, far-apart pairs first would not change results, only which of several
        // violations is reported; keep the order by part for readable reports.
        pairs.sort();
        let chain = set.chain();
        let table = Some(HalfSpace::xy_plane_of(chain.base()));
        Self::new(chain, parts, pairs, table, plate, clearances)
    }

    /// The chain the parts are placed with.
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// The parts, in the order placed capsules and pairs use.
    pub fn parts(&self) -> &[PartShape] {
        &self.parts
    }

    /// The checked pairs, as indices into [`Self::parts`].
    pub fn pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// The table, if the model has one.
    pub fn table(&self) -> Option<&HalfSpace> {
        self.table.as_ref()
    }

    /// The artefact's plate and stand, if the model has them.
    pub fn plate(&self) -> Option<&VerticalPrism> {
        self.plate.as_ref()
    }

    /// Forward kinematics at joint readings q (rad, no joint torques).
    pub fn trace(&self, q: &[f64]) -> Trace {
        self.chain.trace(&self.chain.joint_angles(&JointState::new(q)))
    }

    /// The parts in {W} for a trace of this model's chain, in [`Self::parts`] order.
    pub fn place(&self, trace: &Trace) -> Vec<Capsule> {
        let mut out = Vec::with_capacity(self.parts.len());
        self.place_into(trace, &mut out);
        out
    }

    fn place_into(&self, trace: &Trace, out: &mut Vec<Capsule>) {
        out.clear();
        let base = *self.chain.base();
        out.extend(self.parts.iter().map(|s| {
            let frame = match s.mount {
                Mount::Base => base,
                Mount::Link(j) => trace.link_frame(j),
                Mount::Flange => trace.flange,
            };
            s.local.transformed(&frame)
        }));
    }

    /// The static check of placed parts (from [`Self::place`]): the first violation, in the order
    /// the module lists (pairs, then the table, then the plate).
    pub(crate) fn check_placed(&self, placed: &[Capsule]) -> Result<(), Collision> {
        let cl = &self.clearances;
        for &(i, j) in &self.pairs {
            let d = placed[i].distance(&placed[j]);
            if d < cl.parts {
                return Err(Collision {
                    part: self.parts[i].part,
                    against: Against::Part(self.parts[j].part),
                    penetration: -d,
                    clearance: cl.parts,
                });
            }
        }
        if let Some(table) = &self.table {
            for (s, c) in self.parts.iter().zip(placed) {
                if s.part == Part::BaseColumn {
                    continue;
                }
                let d = table.clearance(c);
                if d < cl.table {
                    return Err(Collision {
                        part: s.part,
                        against: Against::Table,
                        penetration: -d,
                        clearance: cl.table,
                    });
                }
            }
        }
        if let Some(plate) = &self.plate {
            for (s, c) in self.parts.iter().zip(placed) {
                // Above the top face by more than the margin: cannot touch (the common case).
                if c.a.z.min(c.b.z) - c.radius >= plate.top + cl.plate {
                    continue;
                }
                let d = plate.capsule_distance(c);
                if d < cl.plate {
                    return Err(Collision {
                        part: s.part,
                        against: Against::Plate,
                        penetration: -d,
                        clearance: cl.plate,
                    });
                }
            }
        }
        Ok(())
    }

    /// Static check at joint readings q (rad).
    pub fn check_static(&self, q: &[f64]) -> Result<(), Collision> {
        self.check_placed(&self.place(&self.trace(q)))
    }

    /// Number of steps of a linear joint move so that no joint moves more than [`PATH_STEP`]
    /// between samples (at least 1; the move has `steps + 1` samples, endpoints included).
    pub(crate) fn path_steps(from: &[f64], to: &[f64]) -> usize {
        let max = from.iter().zip(to).fold(0.0f64, |m, (a, b)| m.max((b - a).abs()));
        ((max / PATH_STEP).ceil() as usize).max(1)
    }

    /// The linear joint-space move `from` → `to`, sampled at most [`PATH_STEP`] apart on every
    /// joint, endpoints included: every sample must pass the static check. Reports the first
    /// colliding sample along the move. Panics when `from` and `to` differ in length.
    pub fn check_path(&self, from: &[f64], to: &[f64]) -> Result<(), PathCollision> {
        assert_eq!(from.len(), to.len(), "one value per joint");
        let steps = Self::path_steps(from, to);
        let mut q = from.to_vec();
        let mut placed = Vec::with_capacity(self.parts.len());
        for i in 0..=steps {
            let s = i as f64 / steps as f64;
            for j in 0..q.len() {
                q[j] = from[j] + (to[j] - from[j]) * s;
            }
            self.place_into(&self.trace(&q), &mut placed);
            if let Err(collision) = self.check_placed(&placed) {
                return Err(PathCollision { sample: i, samples: steps, q, collision });
            }
        }
        Ok(())
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::model::{Tool, irb120};

    /// The IRB 120 on the floor ({W} = {0}) with a TriCal-sized tool and no plate.
    fn model() -> CollisionModel {
        let tool = Tool { tcp: [0.040, 0.0, 0.130, 0.0, 0.0, 0.0], mass: 1.7, com: Vector3::new(0.03, 0.0, 0.064) };
        let set = ParameterSet::nominal(irb120(), tool, [0.0; 6]);
        let tcp = Vector3::new(0.040, 0.0, 0.130);
        let shape = ToolShape {
            body: vec![Capsule::new(Vector3::zeros(), Vector3::new(0.040, 0.0, 0.095), 0.035)],
            contact: Some(Capsule::new(tcp, tcp, 0.035)),
        };
        CollisionModel::irb120(&set, &LinkRadii::default(), &shape, None, Clearances::default())
    }

    /// At the zero position the parts sit where the IRB 120's drawing puts the joints: axis 2 at
    /// 290 mm, axis 3 at 560 mm, the elbow offset 70 mm up, the wrist centre at (302, 0, 630) mm,
    /// the flange 72 mm further along x.
    #[test]
    fn parts_follow_the_chain() {
        let m = model();
        let placed = m.place(&m.trace(&[0.0; 6]));
        let v = Vector3::new;
        let close = |a: Vector3<f64>, b: Vector3<f64>| (a - b).norm() < 1e-12;
        assert!(close(placed[0].a, v(0.0, 0.0, 0.0)) && close(placed[0].b, v(0.0, 0.0, 0.290)));
        assert!(close(placed[1].a, v(0.0, 0.0, 0.290)) && close(placed[1].b, v(0.0, 0.0, 0.560)));
        assert!(close(placed[2].a, v(0.0, 0.0, 0.560)) && close(placed[2].b, v(0.0, 0.0, 0.630)));
        assert!(close(placed[3].a, v(0.0, 0.0, 0.630)) && close(placed[3].b, v(0.252, 0.0, 0.630)));
        assert!(close(placed[4].a, v(0.302, 0.0, 0.630)) && close(placed[4].b, v(0.374, 0.0, 0.630)));
        let tcp = m.trace(&[0.0; 6]).tcp.t;
        assert!(close(placed[6].a, tcp) && close(placed[6].b, tcp));
        assert_eq!(m.parts().iter().map(|p| p.part).collect::<Vec<_>>()[5..], [Part::Tool(0), Part::ToolContact]);
    }

    /// A tool 70 mm across on a 72 mm flange distance can bend back only so far: with the
    /// forearm ending at the wrist centre, the flange edge reaches the 5 mm clearance at
    /// |q5| ≈ 86.7° (72² + 50² + 2·72·50·cos q5 = 90²).
    #[test]
    fn wrist_bend_is_limited_by_the_tool() {
        let m = model();
        for q6 in [0.0, 90.0, 180.0, -90.0] {
            for sign in [1.0, -1.0] {
                let q = |q5: f64| [0.0, 0.0, 0.0, 0.0, sign * q5 * DEG, q6 * DEG];
                assert_eq!(m.check_static(&q(80.0)), Ok(()));
                let e = m.check_static(&q(95.0)).unwrap_err();
                assert_eq!((e.part, e.against), (Part::Forearm, Against::Part(Part::Tool(0))), "{e}");
            }
        }
    }

    /// A move is checked at no more than 1° per joint, endpoints included, and reports the first
    /// colliding sample: bending the wrist from 0 to 100° fails at the sample past ~86.7°.
    #[test]
    fn path_reports_its_first_colliding_sample() {
        let m = model();
        assert_eq!(CollisionModel::path_steps(&[0.0; 6], &[0.0, 0.0, 0.0, 0.0, 100.0 * DEG, 0.0]), 100);
        assert_eq!(CollisionModel::path_steps(&[0.0; 6], &[0.0; 6]), 1);
        let e = m.check_path(&[0.0; 6], &[0.0, 0.0, 0.0, 0.0, 100.0 * DEG, 0.0]).unwrap_err();
        assert_eq!(e.samples, 100);
        assert!((86..=88).contains(&e.sample), "{e}");
        assert!(
            m.check_static(&e.q).is_err()
                && m.check_static(&[0.0, 0.0, 0.0, 0.0, (e.sample - 1) as f64 * DEG, 0.0]).is_ok()
        );
        assert!(m.check_path(&[0.0; 6], &[0.0, 0.0, 0.0, 0.0, 80.0 * DEG, 0.0]).is_ok());
        let msg = e.to_string();
        assert!(msg.contains("forearm hits tool body") && msg.contains(" mm"), "{msg}");
    }
}

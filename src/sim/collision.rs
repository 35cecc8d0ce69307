//! Capsule collision model of the robot, its tool and the cell (used by [`super::poses`]).
//!
//! Every body is a capsule — the set of points within `radius` of a segment — so every test
//! reduces to an exact segment–segment distance. Robot parts are fixed in link frames and placed
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

use nalgebra::{Vector2, Vector3};

use crate::kinematics::{Chain, Frame, JointState, Param, ParameterSet, Trace};
use crate::units::DEG;

/// A segment `a`–`b` swept by a ball of `radius` (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    pub a: Vector3<f64>,
    pub b: Vector3<f64>,
    pub radius: f64,
}

impl Capsule {
    pub fn new(a: Vector3<f64>, b: Vector3<f64>, radius: f64) -> Self {
        Self { a, b, radius }
    }

    /// The capsule expressed in the parent of `frame` (its endpoints mapped by `frame`).
    pub fn transformed(&self, frame: &Frame) -> Capsule {
        Capsule { a: frame.transform_point(&self.a), b: frame.transform_point(&self.b), radius: self.radius }
    }

    /// Distance between the two surfaces; negative when they overlap (minus the penetration depth).
    pub fn distance(&self, other: &Capsule) -> f64 {
        segment_distance(&self.a, &self.b, &other.a, &other.b) - self.radius - other.radius
    }
}

/// Segments shorter than this (m²) are points: about 1e-15 m.
const DEGENERATE_LEN2: f64 = 1e-30;

/// Parameters (s, t) ∈ [0, 1]² of a closest pair of points `p1 + s·(q1 − p1)` and
/// `p2 + t·(q2 − p2)` of two segments.
///
/// Exact minimisation of the convex quadratic |p1 + s·d1 − p2 − t·d2|² over the unit square
/// (Ericson, *Real-Time Collision Detection*, §5.1.9): the unconstrained s is clamped, t is
/// solved for it and clamped, and s is re-solved for a clamped t. Points (zero-length segments)
/// reduce to point–segment distances. Parallel segments (sin² of the angle below machine ε, where
/// the solve for s is ill-conditioned and the distance is constant along the overlap anyway)
/// start from s = 0.
pub fn closest_segment_params(
    p1: &Vector3<f64>,
    q1: &Vector3<f64>,
    p2: &Vector3<f64>,
    q2: &Vector3<f64>,
) -> (f64, f64) {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.dot(&d1);
    let e = d2.dot(&d2);
    let f = d2.dot(&r);
    if a <= DEGENERATE_LEN2 && e <= DEGENERATE_LEN2 {
        return (0.0, 0.0);
    }
    if a <= DEGENERATE_LEN2 {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = d1.dot(&r);
    if e <= DEGENERATE_LEN2 {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = d1.dot(&d2);
    let denom = a * e - b * b;
    let s = if denom > f64::EPSILON * a * e { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
    let t = (b * s + f) / e;
    if t < 0.0 {
        ((-c / a).clamp(0.0, 1.0), 0.0)
    } else if t > 1.0 {
        (((b - c) / a).clamp(0.0, 1.0), 1.0)
    } else {
        (s, t)
    }
}

/// Exact distance between segments `p1`–`q1` and `p2`–`q2` (either may be a point).
pub fn segment_distance(p1: &Vector3<f64>, q1: &Vector3<f64>, p2: &Vector3<f64>, q2: &Vector3<f64>) -> f64 {
    let (s, t) = closest_segment_params(p1, q1, p2, q2);
    ((p1 + (q1 - p1) * s) - (p2 + (q2 - p2) * t)).norm()
}

/// Distance from point `p` to segment `a`–`b`.
pub fn point_segment_distance(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let d = b - a;
    let len2 = d.dot(&d);
    let t = if len2 <= DEGENERATE_LEN2 { 0.0 } else { ((p - a).dot(&d) / len2).clamp(0.0, 1.0) };
    (a + d * t - p).norm()
}

/// The free side of a plane: points `p` with `normal · (p − point) ≥ 0` (normal of unit length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfSpace {
    pub point: Vector3<f64>,
    pub normal: Vector3<f64>,
}

impl HalfSpace {
    /// The plane z = 0 of `frame` (e.g. the robot's mounting plane from T_0^W), free side +z.
    pub fn xy_plane_of(frame: &Frame) -> Self {
        Self { point: frame.t, normal: frame.r.column(2).into() }
    }

    /// Signed height of `p` above the plane.
    pub fn height(&self, p: &Vector3<f64>) -> f64 {
        self.normal.dot(&(p - self.point))
    }

    /// Height of a capsule's lowest surface point above the plane.
    pub fn clearance(&self, c: &Capsule) -> f64 {
        self.height(&c.a).min(self.height(&c.b)) - c.radius
    }
}

/// A solid vertical prism in {W}: a convex polygon in the XY plane (counter-clockwise corners),
/// from `top` (z, m) downwards without bound (the table below closes it).
#[derive(Clone, Debug, PartialEq)]
pub struct VerticalPrism {
    corners: Vec<Vector2<f64>>,
    /// Outward unit normal of edge i (corner i → corner i+1).
    normals: Vec<Vector2<f64>>,
    pub top: f64,
}

/// Iterations of the golden-section search along a segment: 0.618⁶⁰ ≈ 3e-13 of its length.
const GOLDEN_ITERATIONS: usize = 60;

impl VerticalPrism {
    /// `None` unless the corners (at least three) form a strictly convex counter-clockwise polygon.
    pub fn new(corners: Vec<Vector2<f64>>, top: f64) -> Option<Self> {
        let n = corners.len();
        if n < 3 || !top.is_finite() || corners.iter().any(|c| !c.x.is_finite() || !c.y.is_finite()) {
            return None;
        }
        let mut normals = Vec::with_capacity(n);
        for i in 0..n {
            let e = corners[(i + 1) % n] - corners[i];
            let next = corners[(i + 2) % n] - corners[(i + 1) % n];
            if e.perp(&next) <= 0.0 || e.norm() == 0.0 {
                return None;
            }
            normals.push(Vector2::new(e.y, -e.x) / e.norm());
        }
        Some(Self { corners, normals, top })
    }

    /// The polygon grown by `margin` on every side (each edge moved out by `margin`, corners
    /// mitred, so the result is again a polygon with the same edge directions).
    pub fn grown(corners: &[Vector2<f64>], margin: f64, top: f64) -> Option<Self> {
        let base = Self::new(corners.to_vec(), top)?;
        let n = corners.len();
        let grown = (0..n)
            .map(|i| {
                let (np, nn) = (base.normals[(i + n - 1) % n], base.normals[i]);
                corners[i] + (np + nn) * (margin / (1.0 + np.dot(&nn)))
            })
            .collect();
        Self::new(grown, top)
    }

    pub fn corners(&self) -> &[Vector2<f64>] {
        &self.corners
    }

    /// Signed distance of a point to the prism: Euclidean distance outside, minus the depth below
    /// the nearest face inside.
    pub fn signed_distance(&self, p: &Vector3<f64>) -> f64 {
        let xy = Vector2::new(p.x, p.y);
        let n = self.corners.len();
        let mut inside_depth = f64::NEG_INFINITY;
        for i in 0..n {
            inside_depth = inside_depth.max(self.normals[i].dot(&(xy - self.corners[i])));
        }
        let dz = p.z - self.top;
        if inside_depth <= 0.0 {
            return if dz <= 0.0 { inside_depth.max(dz) } else { dz };
        }
        let mut d2 = f64::INFINITY;
        for i in 0..n {
            let (a, b) = (self.corners[i], self.corners[(i + 1) % n]);
            let e = b - a;
            let t = ((xy - a).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
            d2 = d2.min((a + e * t - xy).norm_squared());
        }
        let d = d2.sqrt();
        if dz <= 0.0 { d } else { d.hypot(dz) }
    }

    /// Signed distance of a segment to the prism: the minimum of the point distance along it.
    /// The signed distance to a convex set is a convex function, so a golden-section search
    /// finds its minimum on the segment to ~1e-13 of the segment's length.
    pub fn segment_signed_distance(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
        let d = b - a;
        let f = |t: f64| self.signed_distance(&(a + d * t));
        let (fa, fb) = (f(0.0), f(1.0));
        if d.norm_squared() <= DEGENERATE_LEN2 {
            return fa;
        }
        let g = (5f64.sqrt() - 1.0) / 2.0;
        let (mut lo, mut hi) = (0.0, 1.0);
        let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        let (mut f1, mut f2) = (f(x1), f(x2));
        for _ in 0..GOLDEN_ITERATIONS {
            if f1 <= f2 {
                hi = x2;
                (x2, f2) = (x1, f1);
                x1 = hi - g * (hi - lo);
                f1 = f(x1);
            } else {
                lo = x1;
                (x1, f1) = (x2, f2);
                x2 = lo + g * (hi - lo);
                f2 = f(x2);
            }
        }
        fa.min(fb).min(f1).min(f2)
    }

    /// Distance between a capsule's surface and the prism; negative when they overlap.
    pub fn capsule_distance(&self, c: &Capsule) -> f64 {
        self.segment_signed_distance(&c.a, &c.b) - c.radius
    }
}

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
    pub part: Part,
    pub against: Against,
    pub penetration: f64,
    pub clearance: f64,
}

/// A joint-space move that collides on the way.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("move collides at sample {sample} of {samples} (q = {}): {collision}", fmt_deg(q))]
pub struct PathCollision {
    /// Index of the colliding sample, 0 = the start, `samples` = the end.
    pub sample: usize,
    pub samples: usize,
    /// The colliding configuration, rad.
    pub q: Vec<f64>,
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
    pub base_column: f64,
    pub upper_arm: f64,
    pub forearm: f64,
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
    pub part: Part,
    pub mount: Mount,
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
    /// table check.
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
    /// values and the chain is `set.chain()`) with a tool body given in the flange frame.
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

    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    pub fn parts(&self) -> &[PartShape] {
        &self.parts
    }

    /// The checked pairs, as indices into [`Self::parts`].
    pub fn pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    pub fn table(&self) -> Option<&HalfSpace> {
        self.table.as_ref()
    }

    pub fn plate(&self) -> Option<&VerticalPrism> {
        self.plate.as_ref()
    }

    pub fn clearances(&self) -> &Clearances {
        &self.clearances
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

    /// The static check of placed parts (from [`Self::place`]).
    pub fn check_placed(&self, placed: &[Capsule]) -> Result<(), Collision> {
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
    pub fn path_steps(from: &[f64], to: &[f64]) -> usize {
        let max = from.iter().zip(to).fold(0.0f64, |m, (a, b)| m.max((b - a).abs()));
        ((max / PATH_STEP).ceil() as usize).max(1)
    }

    /// The linear joint-space move `from` → `to`, sampled at most [`PATH_STEP`] apart on every
    /// joint, endpoints included: every sample must pass the static check. Reports the first
    /// colliding sample along the move.
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
    use proptest::prelude::*;

    /// Brute force: the exact point–segment distance from 4001 points spread along the first
    /// segment. Never below the true distance, and above it by at most half a sample spacing
    /// times the first segment's length (the point distance is 1-Lipschitz along the segment).
    fn brute_force(p1: &Vector3<f64>, q1: &Vector3<f64>, p2: &Vector3<f64>, q2: &Vector3<f64>) -> (f64, f64) {
        let n = 4000;
        let d = (0..=n)
            .map(|i| point_segment_distance(&(p1 + (q1 - p1) * (i as f64 / n as f64)), p2, q2))
            .fold(f64::INFINITY, f64::min);
        (d, (q1 - p1).norm() / (2.0 * n as f64))
    }

    fn v3() -> impl Strategy<Value = Vector3<f64>> {
        (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64).prop_map(|(x, y, z)| Vector3::new(x, y, z))
    }

    /// Random segment pairs, with the special cases drawn often: the second segment parallel to
    /// the first (shifted, scaled, maybe reversed, maybe collinear), either one a point, both
    /// points, or the two identical.
    fn segment_pair() -> impl Strategy<Value = [Vector3<f64>; 4]> {
        (v3(), v3(), v3(), v3(), 0..7u8, -2.0..2.0f64).prop_map(|(p1, q1, p2, q2, kind, k)| match kind {
            0 => [p1, q1, p2, p2 + (q1 - p1) * k],
            1 => [p1, q1, p1 + (q1 - p1) * k, p1 + (q1 - p1) * (k + 0.5)],
            2 => [p1, p1, p2, q2],
            3 => [p1, q1, p2, p2],
            4 => [p1, p1, p2, p2],
            5 => [p1, q1, p1, q1],
            _ => [p1, q1, p2, q2],
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn segment_distance_matches_brute_force(s in segment_pair()) {
            let [p1, q1, p2, q2] = s;
            let exact = segment_distance(&p1, &q1, &p2, &q2);
            let (bf, tol) = brute_force(&p1, &q1, &p2, &q2);
            prop_assert!(exact <= bf + 1e-12, "exact {} above brute force {}", exact, bf);
            prop_assert!(bf - exact <= tol + 1e-12, "exact {} below brute force {} by more than {}", exact, bf, tol);
            // Symmetric in the two segments and in each segment's direction.
            let swapped = segment_distance(&q2, &p2, &q1, &p1);
            prop_assert!((swapped - exact).abs() <= 1e-12);
            let (s, t) = closest_segment_params(&p1, &q1, &p2, &q2);
            prop_assert!((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t));
        }

        /// Signed distance to the prism along a segment against dense sampling of the point
        /// function (exact): never above it, never below it by more than the sampling allows.
        #[test]
        fn prism_segment_distance_matches_sampling(p in v3(), q in v3()) {
            let prism = VerticalPrism::grown(
                &[Vector2::new(0.0, 0.0), Vector2::new(0.3, 0.0), Vector2::new(0.15, 0.26)], 0.06, -0.05,
            ).unwrap();
            let n = 4000;
            let bf = (0..=n)
                .map(|i| prism.signed_distance(&(p + (q - p) * (i as f64 / n as f64))))
                .fold(f64::INFINITY, f64::min);
            let d = prism.segment_signed_distance(&p, &q);
            prop_assert!(d <= bf + 1e-12, "{} vs {}", d, bf);
            prop_assert!(bf - d <= (q - p).norm() / (2.0 * n as f64) + 1e-12, "{} vs {}", d, bf);
        }
    }

    #[test]
    fn segment_distance_known_cases() {
        let v = Vector3::new;
        // Crossing at right angles, 1 apart.
        assert_eq!(segment_distance(&v(-1.0, 0.0, 0.0), &v(1.0, 0.0, 0.0), &v(0.0, -1.0, 1.0), &v(0.0, 1.0, 1.0)), 1.0);
        // Parallel, overlapping: constant distance 2.
        assert_eq!(segment_distance(&v(0.0, 0.0, 0.0), &v(2.0, 0.0, 0.0), &v(1.0, 2.0, 0.0), &v(5.0, 2.0, 0.0)), 2.0);
        // Collinear, disjoint: gap between the ends.
        assert!(
            (segment_distance(&v(0.0, 0.0, 0.0), &v(1.0, 0.0, 0.0), &v(3.0, 0.0, 0.0), &v(2.0, 0.0, 0.0)) - 1.0).abs()
                < 1e-15
        );
        // Point to point.
        assert_eq!(segment_distance(&v(1.0, 1.0, 1.0), &v(1.0, 1.0, 1.0), &v(1.0, 1.0, 4.0), &v(1.0, 1.0, 4.0)), 3.0);
    }

    #[test]
    fn grown_triangle_moves_every_edge_out() {
        let tri = [Vector2::new(0.0, 0.0), Vector2::new(0.3, 0.0), Vector2::new(0.15, 0.15 * 3f64.sqrt())];
        let prism = VerticalPrism::grown(&tri, 0.06, -0.05).unwrap();
        // Each original corner is now 60 mm inside the two adjacent faces.
        for c in tri {
            let d = prism.signed_distance(&Vector3::new(c.x, c.y, -0.5));
            assert!((d + 0.06).abs() < 1e-12, "{d}");
        }
        // Above the top, over the interior: height above the top.
        assert!((prism.signed_distance(&Vector3::new(0.15, 0.05, 0.0)) - 0.05).abs() < 1e-15);
        assert!(VerticalPrism::new(vec![tri[0], tri[2], tri[1]], 0.0).is_none(), "clockwise is refused");
    }
}

#[cfg(test)]
mod model_tests {
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

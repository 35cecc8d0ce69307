//! Measurement pose generation (thesis §4.1, digest §8): identification configurations on the
//! artefact's balls and validation configurations for the laser tracker, free of static
//! collisions and of collisions on the joint-space moves between them.
//!
//! Planning uses what a controller knows: the robot's nominal model and the guessed base pose.
//! Everything is deterministic for a seed (ChaCha8).
//!
//! - Identification: for each ball in turn, the TCP on the ball centre with the TriCal's axis
//!   within ν_max of the ball's rod, orientations drawn uniformly on that cap and about the axis,
//!   one of the valid inverse-kinematics branches drawn at random.
//! - Validation: joint configurations drawn uniformly within the limits, kept when a reflector
//!   nest faces the tracker with a clear line of sight.
//!
//! Every accepted configuration passes the static check of [`CollisionModel`] and the path check
//! of the linear joint move from the previously accepted one (the first from the home
//! configuration), so the list is a runnable measuring sequence in its order.

use std::f64::consts::{PI, TAU};

use nalgebra::{Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::collision::{
    Capsule, Clearances, Collision, CollisionModel, LinkRadii, PathCollision, ToolShape, VerticalPrism,
    segment_distance,
};
use crate::cell::Artefact;
use crate::kinematics::frame::{rot_x, rot_y, rot_z};
use crate::kinematics::model::irb120;
use crate::kinematics::thesis::{TABLE_5_1_NOMINAL_BASE, trical_tool};
use crate::kinematics::{AnalyticIk, Branch, Chain, Frame, ParameterSet, RobotModel, Tool, Trace};
use crate::metrology::BallTriangle;
use crate::units::{DEG, MM};

/// A laser-tracker reflector nest (an SMR seat) on the measuring tool.
#[derive(Clone, Debug, PartialEq)]
pub struct Nest {
    /// The nest as a tool: TCP = the reflector centre in the flange frame (no rotation), payload
    /// = the whole measuring tool's, so it can serve as the tool of a validation session.
    pub tool: Tool,
    /// Unit direction the nest opens towards, in the flange frame.
    pub opening: Vector3<f64>,
    /// Half-angle of the reflector's acceptance cone, rad.
    pub acceptance: f64,
}

impl Nest {
    /// The reflector centre in the flange frame.
    pub fn position(&self) -> Vector3<f64> {
        Vector3::new(self.tool.tcp[0], self.tool.tcp[1], self.tool.tcp[2])
    }
}

/// The three nests of the TriCal (SMR acceptance ±30°), 80 mm up the flange axis: N1 at
/// (0, 60, 80) mm opening +y, N2 at (0, −60, 80) mm opening −y, N3 at (−60, 0, 80) mm opening −x.
/// Payload 1.7 kg at (30, 0, 64) mm like [`trical_tool`].
pub fn trical_nests() -> Vec<Nest> {
    let payload = trical_tool();
    [
        ([0.0, 60.0, 80.0], [0.0, 1.0, 0.0]),
        ([0.0, -60.0, 80.0], [0.0, -1.0, 0.0]),
        ([-60.0, 0.0, 80.0], [-1.0, 0.0, 0.0]),
    ]
    .iter()
    .map(|&(p, n)| Nest {
        tool: Tool { tcp: [p[0] * MM, p[1] * MM, p[2] * MM, 0.0, 0.0, 0.0], ..payload.clone() },
        opening: Vector3::new(n[0], n[1], n[2]),
        acceptance: 30.0 * DEG,
    })
    .collect()
}

/// The TriCal's collision shape in the flange frame: the body, a capsule of radius 35 mm from
/// the flange origin to (40, 0, 95) mm, 35 mm short of the TCP (40, 0, 130) mm; the contact zone,
/// the ball of radius 35 mm about the TCP, which closes on the artefact's ball (on a ball, it
/// stays 15 mm above the plate under 50 mm rods).
pub fn trical_shape() -> ToolShape {
    let tcp = Vector3::new(0.040, 0.0, 0.130);
    ToolShape {
        body: vec![Capsule::new(Vector3::zeros(), Vector3::new(0.040, 0.0, 0.095), 0.035)],
        contact: Some(Capsule::new(tcp, tcp, 0.035)),
    }
}

/// The measuring cell as planning sees it. SI units; {W} is the artefact frame, {0} the robot
/// base.
#[derive(Clone, Debug, PartialEq)]
pub struct CellLayout {
    /// The robot's nominal model (the controller's).
    pub robot: RobotModel,
    /// The measuring tool; its TCP is the constrained ball's centre.
    pub tool: Tool,
    /// The tool's collision shape in the flange frame.
    pub tool_shape: ToolShape,
    pub link_radii: LinkRadii,
    /// Guess of T_0^W as χ (m, rad).
    pub base: [f64; 6],
    /// The ball triangle (defines {W}: balls at z_W = 0) and the ball diameter.
    pub artefact: Artefact,
    /// Length of the vertical rods the balls stand on: the plate's top face is z_W = −rod_length.
    pub rod_length: f64,
    /// How far the plate reaches beyond the ball triangle on every side. The plate and its stand
    /// are one solid prism from the table up to the top face.
    pub plate_margin: f64,
    /// Laser tracker position in {0}, m.
    pub tracker: Vector3<f64>,
    /// Reflector nests for validation.
    pub nests: Vec<Nest>,
    pub clearances: Clearances,
    /// Safe start configuration of every plan, rad.
    pub home: [f64; 6],
}

impl Default for CellLayout {
    /// The thesis's cell (§5): IRB 120 with the TriCal, base guess of Table 5.1, an equilateral
    /// triangle of 300 mm sides (its centroid (150, 86.6, 0) mm is the thesis's calibration-zone
    /// centre) of 12.7 mm balls on 50 mm rods, the plate 60 mm beyond the triangle, the tracker
    /// at (3.0, 0.5, 0.8) m in {0}, home at (0, 0, 0, 0, 30°, 0).
    fn default() -> Self {
        let b = TABLE_5_1_NOMINAL_BASE;
        Self {
            robot: irb120(),
            tool: trical_tool(),
            tool_shape: trical_shape(),
            link_radii: LinkRadii::default(),
            base: [b[0] * MM, b[1] * MM, b[2] * MM, b[3] * DEG, b[4] * DEG, b[5] * DEG],
            artefact: Artefact {
                triangle: BallTriangle::from_distances(0.300, 0.300, 0.300).expect("an equilateral triangle"),
                ball_diameter: 0.0127,
            },
            rod_length: 0.050,
            plate_margin: 0.060,
            tracker: Vector3::new(3.0, 0.5, 0.8),
            nests: trical_nests(),
            clearances: Clearances::default(),
            home: [0.0, 0.0, 0.0, 0.0, 30.0 * DEG, 0.0],
        }
    }
}

/// One planned configuration, in measuring order.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedPose {
    /// Joint targets, rad.
    pub q: [f64; 6],
    /// Identification: the ball (1-based) the TCP sits on.
    pub ball: Option<usize>,
    /// Validation: the nest (0-based index into [`CellLayout::nests`]) facing the tracker.
    pub nest: Option<usize>,
    /// Identification: angle ν between the TriCal's axis and the ball's rod, rad.
    pub nu: Option<f64>,
}

/// Why no plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error("cell layout: {0}")]
    Layout(String),
    #[error("the home configuration is not collision-free: {0}")]
    Home(Collision),
    #[error("ball {ball}: found only {found} of {wanted} identification poses in {attempts} attempts")]
    Ball { ball: usize, found: usize, wanted: usize, attempts: usize },
    #[error("found only {found} of {wanted} validation poses in {attempts} attempts")]
    Validation { found: usize, wanted: usize, attempts: usize },
    #[error(
        "no collision-free move leads to any of the {remaining} configurations left after {sequenced} were sequenced"
    )]
    Sequence { sequenced: usize, remaining: usize },
}

/// Identification planning settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentificationOptions {
    /// Accepted configurations per ball.
    pub per_ball: usize,
    /// Largest angle between the TriCal's axis and the ball's rod, rad.
    pub nu_max: f64,
    /// A ball fails after `per_ball · attempts_per_pose` orientations drawn for it.
    pub attempts_per_pose: usize,
}

impl Default for IdentificationOptions {
    /// 120 per ball and ν ≤ 50° (§4.1); up to 200 draws per wanted pose (the thesis cell needs
    /// about 1.7 on balls 1 and 2, 2.7 on ball 3).
    fn default() -> Self {
        Self { per_ball: 120, nu_max: 50.0 * DEG, attempts_per_pose: 200 }
    }
}

/// How validation configurations are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ValidationSampling {
    /// The thesis's way (§4.1.4): a TCP position uniform in a box around the robot, a nest drawn
    /// at random and turned to face the tracker, uniform spin about the beam, one of the valid
    /// inverse-kinematics branches at random.
    #[default]
    Cartesian,
    /// Joint values uniform inside the (shrunk) limits: harsher, with more configurations at
    /// the edge of the workspace than the thesis measured.
    Joint,
}

/// Validation planning settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidationOptions {
    pub count: usize,
    pub sampling: ValidationSampling,
    /// Cartesian sampling: half-width of the box in x and y of {0} and its z range, m.
    pub box_half_width: f64,
    pub box_z: [f64; 2],
    /// Joint limits are shrunk by this much on both sides when sampling, rad.
    pub joint_margin: f64,
    /// The plan fails after `count · attempts_per_pose` configurations drawn.
    pub attempts_per_pose: usize,
}

impl Default for ValidationOptions {
    /// 506 poses (§4.1, setup 2), 5° inside the limits, up to 200 draws per wanted pose (the
    /// thesis cell needs about 9).
    fn default() -> Self {
        Self {
            count: 506,
            sampling: ValidationSampling::default(),
            box_half_width: 0.70,
            box_z: [-0.10, 1.00],
            joint_margin: 5.0 * DEG,
            attempts_per_pose: 200,
        }
    }
}

/// What happened to the draws of a plan (for one ball, or for the validation plan).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PlanStats {
    pub attempts: usize,
    /// No inverse-kinematics branch within the joint limits.
    pub unreachable: usize,
    /// Failed the static collision check.
    pub collision: usize,
    /// Validation: the TCP below the plate's top face (plus the table clearance).
    pub tcp_low: usize,
    /// Validation: no nest faces the tracker with a clear line of sight.
    pub not_visible: usize,
    /// The move from the previous configuration collides.
    pub path: usize,
    pub accepted: usize,
}

/// A plan with its statistics: one [`PlanStats`] per ball for identification, one in all for
/// validation.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    pub poses: Vec<PlannedPose>,
    pub stats: Vec<PlanStats>,
}

/// Why a single draw was rejected.
#[derive(Clone, Debug, PartialEq)]
enum Reject {
    Unreachable,
    Collision,
    TcpLow,
    NotVisible,
}

/// A cell layout compiled for planning: the nominal chain, its inverse kinematics and the
/// collision model. Build once, plan many times.
#[derive(Clone, Debug)]
pub struct PlanningCell {
    layout: CellLayout,
    chain: Chain,
    ik: AnalyticIk,
    collision: CollisionModel,
    tracker: Vector3<f64>,
}

impl PlanningCell {
    pub fn new(layout: &CellLayout) -> Result<Self, PlanError> {
        let bad = |m: String| PlanError::Layout(m);
        for (name, v) in [("rod_length", layout.rod_length), ("plate_margin", layout.plate_margin)] {
            if !v.is_finite() || v < 0.0 {
                return Err(bad(format!("{name} must be a non-negative number")));
            }
        }
        layout.robot.validate().map_err(|e| bad(e.to_string()))?;
        let nest_ok = |n: &Nest| (n.opening.norm() - 1.0).abs() <= 1e-9 && n.acceptance > 0.0 && n.acceptance <= PI;
        if !layout.nests.iter().all(nest_ok) {
            return Err(bad("nest openings must be unit vectors and acceptances in (0, 180°]".into()));
        }
        let shape = &layout.tool_shape;
        if !shape.body.iter().chain(&shape.contact).all(|c| c.radius >= 0.0) {
            return Err(bad("tool capsule radii must not be negative".into()));
        }
        let set = ParameterSet::nominal(layout.robot.clone(), layout.tool.clone(), layout.base);
        let chain = set.nominal_chain();
        let ik = AnalyticIk::new(&set.model, chain.base(), chain.tool()).map_err(|e| bad(e.to_string()))?;
        let corners: Vec<Vector2<f64>> =
            layout.artefact.triangle.centres().iter().map(|c| Vector2::new(c.x, c.y)).collect();
        let plate = VerticalPrism::grown(&corners, layout.plate_margin, -layout.rod_length)
            .ok_or_else(|| bad("the ball triangle does not make a plate".into()))?;
        let collision =
            CollisionModel::irb120(&set, &layout.link_radii, &layout.tool_shape, Some(plate), layout.clearances);
        collision.check_static(&layout.home).map_err(PlanError::Home)?;
        let tracker = chain.base().transform_point(&layout.tracker);
        Ok(Self { layout: layout.clone(), chain, ik, collision, tracker })
    }

    pub fn layout(&self) -> &CellLayout {
        &self.layout
    }

    /// The nominal chain with the measuring tool.
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    pub fn ik(&self) -> &AnalyticIk {
        &self.ik
    }

    pub fn collision(&self) -> &CollisionModel {
        &self.collision
    }

    /// The tracker in {W}.
    pub fn tracker(&self) -> Vector3<f64> {
        self.tracker
    }

    /// Centre of ball k (1-based) in {W}.
    pub fn ball(&self, k: usize) -> Option<Vector3<f64>> {
        self.layout.artefact.triangle.ball(k)
    }

    /// The TCP frame at a ball `centre` whose z axis (pointing from the TriCal into the ball)
    /// makes the angle `nu` with −Z_W (the rod reversed), tilted towards `azimuth` (about Z_W from
    /// +X_W) and turned by `spin` about its own axis: Rz(azimuth)·Ry(ν)·Rx(π)·Rz(spin).
    pub fn ball_target(centre: &Vector3<f64>, nu: f64, azimuth: f64, spin: f64) -> Frame {
        Frame::new(rot_z(azimuth) * rot_y(nu) * rot_x(PI) * rot_z(spin), *centre)
    }

    /// One identification draw on ball `k`: an orientation uniform on the cap ν ≤ `nu_max`
    /// (cos ν uniform) and uniform about the axis, one of the valid IK branches at random,
    /// kept if it passes the static check. Draws three numbers for the orientation and a fourth
    /// for the branch when some branch is valid.
    fn draw_identification<R: Rng>(
        &self,
        k: usize,
        centre: &Vector3<f64>,
        nu_max: f64,
        rng: &mut R,
    ) -> Result<PlannedPose, Reject> {
        let cos_nu = 1.0 - rng.random::<f64>() * (1.0 - nu_max.cos());
        let nu = cos_nu.clamp(-1.0, 1.0).acos();
        let azimuth = rng.random::<f64>() * TAU;
        let spin = rng.random::<f64>() * TAU;
        let target = Self::ball_target(centre, nu, azimuth, spin);
        let mut solutions = [[0.0; 6]; 8];
        let mut n = 0;
        for b in Branch::ALL {
            if let Ok(q) = self.ik.solve(&target, b) {
                solutions[n] = q;
                n += 1;
            }
        }
        if n == 0 {
            return Err(Reject::Unreachable);
        }
        let q = solutions[rng.random_range(0..n)];
        self.collision.check_static(&q).map_err(|_| Reject::Collision)?;
        Ok(PlannedPose { q, ball: Some(k), nest: None, nu: Some(nu) })
    }

    fn centre(&self, k: usize) -> Result<Vector3<f64>, PlanError> {
        self.ball(k).ok_or_else(|| PlanError::Layout(format!("there is no ball {k}")))
    }

    /// A pool of statically collision-free identification configurations on ball `k` (no path
    /// checks: for a later selection, e.g. DETMAX, whose chosen subset is then sequenced and
    /// path-checked with [`Self::check_sequence`]).
    pub fn identification_candidates<R: Rng>(
        &self,
        k: usize,
        nu_max: f64,
        count: usize,
        max_attempts: usize,
        rng: &mut R,
    ) -> Result<Vec<PlannedPose>, PlanError> {
        let centre = self.centre(k)?;
        let mut out = Vec::with_capacity(count);
        let mut attempts = 0;
        while out.len() < count {
            if attempts == max_attempts {
                return Err(PlanError::Ball { ball: k, found: out.len(), wanted: count, attempts });
            }
            attempts += 1;
            if let Ok(p) = self.draw_identification(k, &centre, nu_max, rng) {
                out.push(p);
            }
        }
        Ok(out)
    }

    /// Identification plan: `per_ball` configurations on ball 1, then ball 2, then ball 3, each
    /// reachable from the previous one (the first from home) by a collision-free joint move.
    pub fn plan_identification(&self, opts: &IdentificationOptions, seed: u64) -> Result<Plan, PlanError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut poses = Vec::with_capacity(3 * opts.per_ball);
        let mut stats = Vec::with_capacity(3);
        let mut prev = self.layout.home;
        let max_attempts = opts.per_ball.saturating_mul(opts.attempts_per_pose);
        for k in 1..=3 {
            let centre = self.centre(k)?;
            let mut st = PlanStats::default();
            while st.accepted < opts.per_ball {
                if st.attempts == max_attempts {
                    return Err(PlanError::Ball {
                        ball: k,
                        found: st.accepted,
                        wanted: opts.per_ball,
                        attempts: st.attempts,
                    });
                }
                st.attempts += 1;
                match self.draw_identification(k, &centre, opts.nu_max, &mut rng) {
                    Err(r) => st.count(&r),
                    Ok(p) => {
                        if self.collision.check_path(&prev, &p.q).is_err() {
                            st.path += 1;
                        } else {
                            st.accepted += 1;
                            prev = p.q;
                            poses.push(p);
                        }
                    }
                }
            }
            stats.push(st);
        }
        Ok(Plan { poses, stats })
    }

    /// The nest's reflector centre and opening direction in {W}.
    pub fn nest_in_world(&self, trace: &Trace, nest: usize) -> (Vector3<f64>, Vector3<f64>) {
        let n = &self.layout.nests[nest];
        (trace.flange.transform_point(&n.position()), trace.flange.r * n.opening)
    }

    /// Angle between nest `nest`'s opening and the direction from it to the tracker, rad.
    pub fn nest_angle(&self, trace: &Trace, nest: usize) -> f64 {
        let (p, n) = self.nest_in_world(trace, nest);
        let to = (self.tracker - p).normalize();
        n.dot(&to).clamp(-1.0, 1.0).acos()
    }

    /// Whether the beam from nest `nest` to the tracker clears every placed part (from
    /// [`CollisionModel::place`]) — the beam as a segment of zero radius — and the plate.
    pub fn line_of_sight(&self, trace: &Trace, placed: &[Capsule], nest: usize) -> bool {
        let (p, _) = self.nest_in_world(trace, nest);
        let t = self.tracker;
        placed.iter().all(|c| segment_distance(&p, &t, &c.a, &c.b) > c.radius)
            && self.collision.plate().is_none_or(|plate| plate.segment_signed_distance(&p, &t) > 0.0)
    }

    /// The nest that measures configuration q (rad): among the nests facing the tracker within
    /// their acceptance and seeing it, the most directly facing one.
    pub fn visible_nest(&self, trace: &Trace, placed: &[Capsule]) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for k in 0..self.layout.nests.len() {
            let angle = self.nest_angle(trace, k);
            if angle <= self.layout.nests[k].acceptance
                && best.is_none_or(|(_, a)| angle < a)
                && self.line_of_sight(trace, placed, k)
            {
                best = Some((k, angle));
            }
        }
        best.map(|(k, _)| k)
    }

    /// The validation checks of one configuration except the path: static collisions, the TCP
    /// above the plate's top face (plus the table clearance), and a nest seeing the tracker.
    /// Returns that nest.
    fn validation_nest(&self, q: &[f64; 6]) -> Result<usize, Reject> {
        let trace = self.collision.trace(q);
        let placed = self.collision.place(&trace);
        self.collision.check_placed(&placed).map_err(|_| Reject::Collision)?;
        if trace.tcp.t.z < -self.layout.rod_length + self.layout.clearances.table {
            return Err(Reject::TcpLow);
        }
        self.visible_nest(&trace, &placed).ok_or(Reject::NotVisible)
    }

    /// The nest that would measure q in a validation plan, or `None` when q fails a validation
    /// check other than the path.
    pub fn validation_check(&self, q: &[f64; 6]) -> Option<usize> {
        self.validation_nest(q).ok()
    }

    /// Validation plan: `count` configurations drawn uniformly in the joint limits (shrunk by
    /// the margin; axis 6 within ±180°, as further turns change nothing the tracker sees),
    /// each passing [`Self::validation_check`] and reachable from the previous one.
    pub fn plan_validation(&self, opts: &ValidationOptions, seed: u64) -> Result<Plan, PlanError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut ranges = [[0.0; 2]; 6];
        for (j, r) in ranges.iter_mut().enumerate() {
            let [lo, hi] = self.layout.robot.links[j].limits;
            *r = [lo + opts.joint_margin, hi - opts.joint_margin];
            if j == 5 {
                *r = [r[0].max(-PI), r[1].min(PI)];
            }
            let non_empty = r[0] < r[1];
            if !non_empty {
                return Err(PlanError::Layout(format!("joint {} has no range left inside the margin", j + 1)));
            }
        }
        let mut poses = Vec::with_capacity(opts.count);
        let mut st = PlanStats::default();
        let mut prev = self.layout.home;
        let max_attempts = opts.count.saturating_mul(opts.attempts_per_pose);
        while st.accepted < opts.count {
            if st.attempts == max_attempts {
                return Err(PlanError::Validation { found: st.accepted, wanted: opts.count, attempts: st.attempts });
            }
            st.attempts += 1;
            let q = match opts.sampling {
                ValidationSampling::Joint => std::array::from_fn(|j| rng.random_range(ranges[j][0]..ranges[j][1])),
                ValidationSampling::Cartesian => match self.draw_cartesian(opts, &mut rng) {
                    Ok(q) => q,
                    Err(r) => {
                        st.count(&r);
                        continue;
                    }
                },
            };
            match self.validation_nest(&q) {
                Err(r) => st.count(&r),
                Ok(nest) => {
                    if self.collision.check_path(&prev, &q).is_err() {
                        st.path += 1;
                    } else {
                        st.accepted += 1;
                        prev = q;
                        poses.push(PlannedPose { q, ball: None, nest: Some(nest), nu: None });
                    }
                }
            }
        }
        Ok(Plan { poses, stats: vec![st] })
    }

    /// One Cartesian validation draw (§4.1.4): the measuring tool's TCP uniform in the box (in
    /// {0}), a random nest whose opening points from the TCP at the tracker, uniform spin about
    /// that direction, a random valid branch. The nest sits a few centimetres from the TCP, so
    /// it faces the tracker within a few degrees; [`Self::validation_check`] decides.
    fn draw_cartesian<R: Rng>(&self, opts: &ValidationOptions, rng: &mut R) -> Result<[f64; 6], Reject> {
        let w = opts.box_half_width;
        let p0 = Vector3::new(
            rng.random_range(-w..w),
            rng.random_range(-w..w),
            rng.random_range(opts.box_z[0]..opts.box_z[1]),
        );
        let p = self.chain.base().transform_point(&p0);
        let nest = &self.layout.nests[rng.random_range(0..self.layout.nests.len())];
        let spin = rng.random::<f64>() * TAU;
        let to = self.tracker - p;
        let d = to.try_normalize(1e-9).ok_or(Reject::Unreachable)?;
        let align = nalgebra::Rotation3::rotation_between(&nest.opening, &d).unwrap_or_else(|| {
            nalgebra::Rotation3::from_axis_angle(
                &nalgebra::Unit::new_normalize(nest.opening.cross(&Vector3::z()) + 1e-3 * Vector3::x()),
                PI,
            )
        });
        let r_flange = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_unchecked(d), spin) * align;
        let tool = self.chain.tool();
        let target = Frame::new(r_flange.matrix() * tool.r, p);
        let mut solutions = [[0.0; 6]; 8];
        let mut n = 0;
        for b in Branch::ALL {
            if let Ok(q) = self.ik.solve(&target, b) {
                solutions[n] = q;
                n += 1;
            }
        }
        if n == 0 {
            return Err(Reject::Unreachable);
        }
        Ok(solutions[rng.random_range(0..n)])
    }

    /// A measuring order for a set of configurations (e.g. a DETMAX selection whose planned order
    /// no longer holds once poses were dropped): from home, always move to the nearest remaining
    /// configuration (largest joint displacement, what a joint move's duration follows) whose joint
    /// move is collision-free; when none is, slot one in between two sequenced configurations whose
    /// moves into and out of it are free. Fails, saying how far it got, when neither works.
    pub fn sequence(&self, mut left: Vec<PlannedPose>) -> Result<Vec<PlannedPose>, PlanError> {
        let dist = |a: &[f64; 6], b: &[f64; 6]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        let mut out = Vec::with_capacity(left.len());
        let mut prev = self.layout.home;
        while !left.is_empty() {
            let mut order: Vec<usize> = (0..left.len()).collect();
            order.sort_by(|&a, &b| dist(&prev, &left[a].q).total_cmp(&dist(&prev, &left[b].q)).then(a.cmp(&b)));
            if let Some(i) = order.into_iter().find(|&i| self.collision.check_path(&prev, &left[i].q).is_ok()) {
                let p = left.remove(i);
                prev = p.q;
                out.push(p);
                continue;
            }
            // Stuck: slot a remaining configuration between two sequenced ones it can be reached
            // from and left to, then carry on from the end.
            let home = self.layout.home;
            let slot = (0..left.len()).find_map(|i| {
                (0..out.len()).find_map(|k| {
                    let before = if k == 0 { home } else { out[k - 1].q };
                    let free = self.collision.check_path(&before, &left[i].q).is_ok()
                        && self.collision.check_path(&left[i].q, &out[k].q).is_ok();
                    free.then_some((i, k))
                })
            });
            let Some((i, k)) = slot else {
                return Err(PlanError::Sequence { sequenced: out.len(), remaining: left.len() });
            };
            let p = left.remove(i);
            out.insert(k, p);
        }
        Ok(out)
    }

    /// Path-check a measuring sequence from home: `Err((i, e))` when the move into pose i fails.
    pub fn check_sequence(&self, poses: &[PlannedPose]) -> Result<(), (usize, PathCollision)> {
        let mut prev = self.layout.home;
        for (i, p) in poses.iter().enumerate() {
            self.collision.check_path(&prev, &p.q).map_err(|e| (i, e))?;
            prev = p.q;
        }
        Ok(())
    }
}

impl PlanStats {
    fn count(&mut self, r: &Reject) {
        match r {
            Reject::Unreachable => self.unreachable += 1,
            Reject::Collision => self.collision += 1,
            Reject::TcpLow => self.tcp_low += 1,
            Reject::NotVisible => self.not_visible += 1,
        }
    }
}

/// Identification plan of a layout with the default ν ≤ 50°: `per_ball` configurations on each
/// of the three balls, in measuring order (ball 1's, then 2's, then 3's).
pub fn plan_identification(layout: &CellLayout, per_ball: usize, seed: u64) -> Result<Vec<PlannedPose>, PlanError> {
    let opts = IdentificationOptions { per_ball, ..Default::default() };
    Ok(PlanningCell::new(layout)?.plan_identification(&opts, seed)?.poses)
}

/// Validation plan of a layout: `count` configurations in measuring order, each with its nest.
pub fn plan_validation(layout: &CellLayout, count: usize, seed: u64) -> Result<Vec<PlannedPose>, PlanError> {
    let opts = ValidationOptions { count, ..Default::default() };
    Ok(PlanningCell::new(layout)?.plan_validation(&opts, seed)?.poses)
}

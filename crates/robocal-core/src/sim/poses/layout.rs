//! The lab as planning sees it: the robot's nominal model and base guess, the measuring tool
//! and its reflector nests, the artefact on its plate, the tracker, the home configuration; and
//! its compilation into a [`PlanningCell`] (nominal chain, inverse kinematics, collision model).

use std::f64::consts::PI;

use nalgebra::{Vector2, Vector3};

use super::{PlanError, PlanningCell};
use crate::cell::Artefact;
use crate::kinematics::model::irb120;
use crate::kinematics::thesis::{TABLE_5_1_NOMINAL_BASE, trical_tool};
use crate::kinematics::{AnalyticIk, ParameterSet, RobotModel, Tool};
use crate::metrology::BallTriangle;
use crate::sim::collision::{Clearances, CollisionModel, LinkRadii, ToolShape};
use crate::sim::geometry::{Capsule, VerticalPrism};
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

/// Three reflectors on a plate, all opening the same way (−x of the flange frame, away from the
/// TriCal's TCP side), at the TriCal nests' positions (0, 60, 80), (0, −60, 80), (−60, 0, 80) mm:
/// a tracker reads all three wherever one sees it unoccluded (`simulate --reflector-plate`), as
/// in the three-reflector format. Payload as [`trical_nests`].
pub fn reflector_plate() -> Vec<Nest> {
    trical_nests().into_iter().map(|n| Nest { opening: Vector3::new(-1.0, 0.0, 0.0), ..n }).collect()
}

/// The TriCal's collision shape in the flange frame: the body, a capsule of radius 35 mm from
/// the flange origin to (40, 0, 95) mm, 35 mm short of the TCP (40, 0, 130) mm; the contact zone,
/// the ball of radius 35 mm about the TCP, which closes on the artefact's ball (on a ball, it
/// stays 15 mm above the plate under 50 mm rods).
pub(crate) fn trical_shape() -> ToolShape {
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
    /// Capsule radii of the robot's links.
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
    /// Safety margins of the collision checks.
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

impl PlanningCell {
    /// Compile a layout for planning: the nominal chain with the measuring tool on the base
    /// guess, its analytic inverse kinematics, and the IRB 120 capsule model
    /// ([`CollisionModel::irb120`]) with the plate grown from the ball triangle.
    ///
    /// [`PlanError::Layout`] when `rod_length` or `plate_margin` is negative or not finite, the
    /// robot model is invalid or has no analytic inverse kinematics, a nest's opening is not a
    /// unit vector or its acceptance not in (0, 180°], a tool capsule radius is negative, or the
    /// triangle makes no plate; [`PlanError::Home`] when the home configuration collides.
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::Frame;
    use crate::sim::collision::{Against, Part};

    /// The default layout is the thesis's cell (§5, Table 5.1): the nominal base in SI, the
    /// 300 mm triangle on 50 mm rods, three nests 80 mm up the flange axis opening outwards with
    /// ±30° acceptance, the TriCal's contact zone centred on its TCP; it compiles, with the
    /// tracker moved into {W} and a collision-free home.
    #[test]
    fn default_layout_is_the_thesis_cell() {
        let l = CellLayout::default();
        let b = TABLE_5_1_NOMINAL_BASE;
        for k in 0..3 {
            assert!((l.base[k] - b[k] / 1000.0).abs() < 1e-15 && (l.base[3 + k] - b[3 + k].to_radians()).abs() < 1e-15);
        }
        let c = l.artefact.triangle.centres();
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            assert!(((c[i] - c[j]).norm() - 0.300).abs() < 1e-12);
        }
        assert_eq!((l.rod_length, l.plate_margin, l.artefact.ball_diameter), (0.050, 0.060, 0.0127));
        assert_eq!(l.nests.len(), 3);
        for n in &l.nests {
            assert!((n.opening.norm() - 1.0).abs() < 1e-15 && (n.acceptance - 30.0 * DEG).abs() < 1e-15);
            assert!((n.position().z - 0.080).abs() < 1e-15 && n.position().dot(&n.opening) > 0.059, "{n:?}");
            assert_eq!((n.tool.mass, n.tool.com), (l.tool.mass, l.tool.com));
        }
        let tcp = Vector3::new(l.tool.tcp[0], l.tool.tcp[1], l.tool.tcp[2]);
        let contact = l.tool_shape.contact.unwrap();
        assert_eq!((contact.a, contact.b, contact.radius), (tcp, tcp, 0.035));
        let body = l.tool_shape.body[0];
        assert!(((tcp - body.b).norm() - 0.035).abs() < 1e-15, "the body stops 35 mm short of the TCP");

        let cell = PlanningCell::new(&l).unwrap();
        let tracker = Frame::from_xyzabc(&l.base).transform_point(&l.tracker);
        assert!((cell.tracker() - tracker).norm() < 1e-12);
        let (dp, da) = cell.chain().base().distance(&Frame::from_xyzabc(&l.base));
        assert!(dp < 1e-12 && da < 1e-12, "the planner's chain stands on the base guess");
        assert_eq!(cell.collision().check_static(&l.home), Ok(()));
    }

    /// Layouts planning cannot use are refused, saying why.
    #[test]
    fn unusable_layouts_are_refused() {
        let refused = |l: &CellLayout| match PlanningCell::new(l) {
            Err(PlanError::Layout(why)) => why,
            other => panic!("{other:?}"),
        };
        assert!(refused(&CellLayout { rod_length: -0.01, ..Default::default() }).contains("rod_length"));
        assert!(refused(&CellLayout { plate_margin: f64::NAN, ..Default::default() }).contains("plate_margin"));
        let mut l = CellLayout::default();
        l.nests[1].opening *= 2.0;
        assert!(refused(&l).contains("unit vectors"));
        let mut l = CellLayout::default();
        l.nests[2].acceptance = 0.0;
        assert!(refused(&l).contains("acceptances"));
        let mut l = CellLayout::default();
        l.tool_shape.body[0].radius = -0.001;
        assert!(refused(&l).contains("radii"));
        // Home with the forearm folded back into the base column.
        let l = CellLayout { home: [0.0, 110.0 * DEG, 70.0 * DEG, 0.0, 0.0, 0.0], ..Default::default() };
        match PlanningCell::new(&l) {
            Err(PlanError::Home(c)) => {
                assert_eq!((c.part, c.against), (Part::BaseColumn, Against::Part(Part::Forearm)))
            }
            other => panic!("{other:?}"),
        }
    }
}

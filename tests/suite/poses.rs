//! Measurement-pose planning on the thesis cell. Every planned pose is re-checked here apart from
//! the planner: forward kinematics of a freshly built nominal chain, the ν cone, the nest's view
//! of the tracker, the static collision check and the move from the previous pose.

use std::f64::consts::PI;
use std::sync::OnceLock;

use nalgebra::Vector3;
use robocal::kinematics::frame::{rot_x, rot_z};
use robocal::kinematics::model::irb120;
use robocal::kinematics::{Branch, Frame, JointState, ParameterSet};
use robocal::sim::collision::{Against, Part, segment_distance};
use robocal::sim::poses::{
    CellLayout, IdentificationOptions, PlanError, PlannedPose, PlanningCell, plan_identification, plan_validation,
};

const DEG: f64 = PI / 180.0;
const SEED: u64 = 2016;

struct Plans {
    layout: CellLayout,
    cell: PlanningCell,
    identification: Vec<PlannedPose>,
    validation: Vec<PlannedPose>,
}

/// The default plans, computed once for all tests of this file.
fn plans() -> &'static Plans {
    static PLANS: OnceLock<Plans> = OnceLock::new();
    PLANS.get_or_init(|| {
        let layout = CellLayout::default();
        Plans {
            cell: PlanningCell::new(&layout).unwrap(),
            identification: plan_identification(&layout, 120, SEED).unwrap(),
            validation: plan_validation(&layout, 506, SEED).unwrap(),
            layout,
        }
    })
}

fn within_limits(layout: &CellLayout, q: &[f64; 6]) -> bool {
    q.iter().enumerate().all(|(j, &v)| layout.robot.within_limits(j, v))
}

/// Static check of each pose and the path check of the move into it from the previous one
/// (the first from home).
fn assert_runnable(cell: &PlanningCell, poses: &[PlannedPose]) {
    let c = cell.collision();
    let mut prev = cell.layout().home;
    for (i, p) in poses.iter().enumerate() {
        c.check_static(&p.q).unwrap_or_else(|e| panic!("pose {i}: {e}"));
        c.check_path(&prev, &p.q).unwrap_or_else(|e| panic!("move into pose {i}: {e}"));
        prev = p.q;
    }
}

#[test]
fn defaults_give_360_and_506_poses_deterministically() {
    let p = plans();
    assert_eq!(p.identification.len(), 360);
    assert_eq!(p.validation.len(), 506);
    let bits = |v: &[PlannedPose]| -> Vec<u64> {
        v.iter().flat_map(|p| p.q.iter().chain(p.nu.iter()).map(|x| x.to_bits()).collect::<Vec<_>>()).collect()
    };
    let again = plan_identification(&p.layout, 120, SEED).unwrap();
    assert_eq!(again, p.identification);
    assert_eq!(bits(&again), bits(&p.identification));
    let again = plan_validation(&p.layout, 506, SEED).unwrap();
    assert_eq!(again, p.validation);
    assert_eq!(bits(&again), bits(&p.validation));
    let other = plan_identification(&p.layout, 120, SEED + 1).unwrap();
    assert_eq!(other.len(), 360);
    assert!(other.iter().zip(&p.identification).all(|(a, b)| a.q != b.q));
    let other = plan_validation(&p.layout, 506, SEED + 1).unwrap();
    assert_eq!(other.len(), 506);
    assert!(other.iter().zip(&p.validation).all(|(a, b)| a.q != b.q));
}

#[test]
fn identification_poses_sit_on_their_balls_inside_the_cone() {
    let p = plans();
    // An independent nominal chain with the TriCal, built from the layout's parts.
    let chain = ParameterSet::nominal(irb120(), p.layout.tool.clone(), p.layout.base).nominal_chain();
    for (i, pose) in p.identification.iter().enumerate() {
        // Measuring order: ball 1's 120, then ball 2's, then ball 3's.
        let k = i / 120 + 1;
        assert_eq!((pose.ball, pose.nest), (Some(k), None), "pose {i}");
        assert!(within_limits(&p.layout, &pose.q), "pose {i}: {:?}", pose.q);
        let tcp = chain.fk(&JointState::new(&pose.q));
        let centre = p.layout.artefact.triangle.ball(k).unwrap();
        assert!((tcp.t - centre).norm() < 1e-9, "pose {i}: TCP {:.3e} m off ball {k}", (tcp.t - centre).norm());
        // ν: angle between the tool z axis (into the ball) and −Z_W.
        let z: Vector3<f64> = tcp.r.column(2).into();
        let nu = z.dot(&-Vector3::z()).clamp(-1.0, 1.0).acos();
        assert!(nu <= 50.0 * DEG + 1e-9, "pose {i}: ν = {:.3}°", nu / DEG);
        assert!((nu - pose.nu.unwrap()).abs() < 1e-7, "pose {i}: recorded ν {} vs {}", pose.nu.unwrap(), nu);
    }
    // The cone is used, not just its axis.
    let max_nu = p.identification.iter().map(|q| q.nu.unwrap()).fold(0.0, f64::max);
    assert!(max_nu > 45.0 * DEG, "largest ν {:.1}°", max_nu / DEG);
}

#[test]
fn identification_sequence_is_collision_free() {
    let p = plans();
    assert_runnable(&p.cell, &p.identification);
    assert_eq!(p.cell.check_sequence(&p.identification), Ok(()));
}

#[test]
fn validation_poses_see_the_tracker_and_are_collision_free() {
    let p = plans();
    let c = p.cell.collision();
    let tracker = Frame::from_xyzabc(&p.layout.base).transform_point(&p.layout.tracker);
    for (i, pose) in p.validation.iter().enumerate() {
        assert_eq!((pose.ball, pose.nu), (None, None));
        assert!(within_limits(&p.layout, &pose.q), "pose {i}: {:?}", pose.q);
        let n = pose.nest.unwrap();
        let nest = &p.layout.nests[n];
        // The nest as the TCP of its own tool on a fresh nominal chain.
        let f = ParameterSet::nominal(irb120(), nest.tool.clone(), p.layout.base)
            .nominal_chain()
            .fk(&JointState::new(&pose.q));
        let opening = f.r * nest.opening;
        let angle = opening.dot(&(tracker - f.t).normalize()).clamp(-1.0, 1.0).acos();
        assert!(angle <= 30.0 * DEG + 1e-12, "pose {i}: nest {n} at {:.2}° from the tracker", angle / DEG);
        // Line of sight: the beam clears every placed capsule and the plate.
        let trace = c.trace(&pose.q);
        let placed = c.place(&trace);
        for (shape, cap) in c.parts().iter().zip(&placed) {
            let d = segment_distance(&f.t, &tracker, &cap.a, &cap.b) - cap.radius;
            assert!(d > 0.0, "pose {i}: the beam from nest {n} passes {:.1} mm inside the {}", -d * 1e3, shape.part);
        }
        assert!(c.plate().unwrap().segment_signed_distance(&f.t, &tracker) > 0.0, "pose {i}: beam through the plate");
        // The TCP (the TriCal's ball) above the plate's top face.
        assert!(trace.tcp.t.z > -p.layout.rod_length, "pose {i}: TCP at z_W = {:.1} mm", trace.tcp.t.z * 1e3);
        assert_eq!(p.cell.validation_check(&pose.q), Some(n));
    }
    assert_runnable(&p.cell, &p.validation);
    // All three nests get used.
    for n in 0..3 {
        assert!(p.validation.iter().filter(|v| v.nest == Some(n)).count() > 50, "nest {n}");
    }
}

/// The frame with the tool pointing straight down (−z of {0}) at `p` in {0}, in {W}.
fn tool_down(cell: &PlanningCell, p: Vector3<f64>, spin: f64) -> Frame {
    cell.chain().base().compose(&Frame::new(rot_z(spin) * rot_x(PI), p))
}

#[test]
fn collision_model_catches_known_collisions() {
    let p = plans();
    let c = p.cell.collision();
    assert_eq!(c.check_static(&p.layout.home), Ok(()));

    // Upper arm leaning 110° forward, forearm folded 70° down: it points straight back into the
    // base column, 162 mm above the table.
    let e = c.check_static(&[0.0, 110.0 * DEG, 70.0 * DEG, 0.0, 0.0, 0.0]).unwrap_err();
    assert_eq!((e.part, e.against), (Part::BaseColumn, Against::Part(Part::Forearm)), "{e}");
    assert!(e.penetration > 0.1, "{e}");
    let msg = e.to_string();
    assert!(msg.contains("base column") && msg.contains("forearm") && msg.contains(" mm"), "{msg}");

    // The TCP 20 mm below the table, pointing down, beside the robot (clear of the plate): the
    // tool body's end is 35 mm above the TCP with a 35 mm radius, so it is 20 mm into the table.
    let q = p.cell.ik().solve(&tool_down(&p.cell, Vector3::new(0.0, -0.4, -0.02), 0.0), Branch::ALL[0]).unwrap();
    let e = c.check_static(&q).unwrap_err();
    assert_eq!((e.part, e.against), (Part::Tool(0), Against::Table), "{e}");
    assert!((e.penetration - 0.020).abs() < 1e-9, "{e}");

    // The TCP 20 mm below the plate's top face over the triangle's centroid, pointing down.
    let below = p.layout.artefact.triangle.centroid() - Vector3::new(0.0, 0.0, p.layout.rod_length + 0.020);
    let q = p.cell.ik().solve(&PlanningCell::ball_target(&below, 0.0, 0.0, 0.0), Branch::ALL[0]).unwrap();
    let e = c.check_static(&q).unwrap_err();
    assert_eq!((e.part, e.against), (Part::Tool(0), Against::Plate), "{e}");
    assert!((e.penetration - 0.020).abs() < 1e-9, "{e}");
    assert!(e.to_string().contains("tool body hits artefact plate: penetration 20.000 mm"), "{e}");
}

/// Both ends clear, the middle of the move through the plate: only the path check sees it.
#[test]
fn path_check_catches_a_sweep_through_the_plate() {
    let p = plans();
    let c = p.cell.collision();
    // Tool down 100 mm above the table, 300 mm in front of axis 1: inside the plate.
    let mid = p.cell.ik().solve(&tool_down(&p.cell, Vector3::new(0.3, 0.0, 0.1), 0.0), Branch::ALL[0]).unwrap();
    assert_eq!(c.check_static(&mid).unwrap_err().against, Against::Plate);
    let (mut from, mut to) = (mid, mid);
    from[0] += 80.0 * DEG;
    to[0] -= 80.0 * DEG;
    assert_eq!(c.check_static(&from), Ok(()));
    assert_eq!(c.check_static(&to), Ok(()));
    let e = c.check_path(&from, &to).unwrap_err();
    assert_eq!(e.collision.against, Against::Plate, "{e}");
    assert_eq!(e.samples, 160);
    assert!(e.sample > 0 && e.sample < 80, "{e}");
}

#[test]
fn an_unreachable_ball_is_an_error_naming_it() {
    // The robot 250 mm further from the artefact: ball 3 is out of reach.
    let mut layout = CellLayout::default();
    layout.base[1] -= 0.250;
    match plan_identification(&layout, 5, 1) {
        Err(PlanError::Ball { ball: 3, found: 0, wanted: 5, attempts: 1000 }) => {}
        other => panic!("{other:?}"),
    }
    let e = plan_identification(&layout, 5, 1).unwrap_err().to_string();
    assert!(e.contains("ball 3") && e.contains("0 of 5"), "{e}");
}

#[test]
fn candidate_pools_are_collision_free_and_seeded() {
    use rand::SeedableRng;
    let p = plans();
    let pool = |seed| {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        p.cell.identification_candidates(2, 50.0 * DEG, 40, 4000, &mut rng).unwrap()
    };
    let a = pool(7);
    assert_eq!(a.len(), 40);
    assert_eq!(a, pool(7));
    assert_ne!(a, pool(8));
    let centre = p.layout.artefact.triangle.ball(2).unwrap();
    for c in &a {
        assert_eq!(c.ball, Some(2));
        assert_eq!(p.cell.collision().check_static(&c.q), Ok(()));
        assert!((p.cell.chain().fk(&JointState::new(&c.q)).t - centre).norm() < 1e-9);
    }
    // The options' defaults are the thesis's.
    let d = IdentificationOptions::default();
    assert_eq!((d.per_ball, (d.nu_max / DEG).round()), (120, 50.0));
}

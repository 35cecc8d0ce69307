//! Property tests of the kinematics invariants and the file formats.

use proptest::prelude::*;
use robocal::domain::ParameterSetDoc;
use robocal::kinematics::frame::wrap_pi;
use robocal::kinematics::model::irb120;
use robocal::kinematics::{AnalyticIk, JointState, Param, ParameterSet, Tool};
use robocal::metrology::TriCal;

fn irb_q() -> impl Strategy<Value = [f64; 6]> {
    let m = irb120();
    let l: Vec<[f64; 2]> = m.links.iter().map(|l| l.limits).collect();
    (
        l[0][0]..l[0][1],
        l[1][0]..l[1][1],
        l[2][0]..l[2][1],
        l[3][0]..l[3][1],
        prop_oneof![l[4][0]..-0.01, 0.01..l[4][1]],
        -std::f64::consts::PI..std::f64::consts::PI,
    )
        .prop_map(|(a, b, c, d, e, f)| [a, b, c, d, e, f])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// IK(FK(q)) on q's own branch gives q back; the rotation stays orthonormal.
    #[test]
    fn closed_form_inverts_forward_kinematics(q in irb_q()) {
        let set = ParameterSet::nominal(irb120(), Tool { tcp: [0.03, 0.0, 0.12, 0.0, 0.0, 0.0], mass: 0.0, com: Default::default() }, [0.0; 6]);
        let chain = set.nominal_chain();
        let ik = AnalyticIk::new(&set.model, chain.base(), chain.tool()).unwrap();
        let f = chain.fk(&JointState::new(&q));
        prop_assert!((f.r.transpose() * f.r - nalgebra::Matrix3::identity()).abs().max() < 1e-14);
        let back = ik.solve_unchecked(&f, ik.classify(&q)).unwrap();
        for j in 0..6 {
            prop_assert!(wrap_pi(back[j] - q[j]).abs() < 1e-7, "joint {}: {:?} vs {:?}", j, back, q);
        }
    }

    /// Any parameter perturbation survives the JSON round trip to 5e-12 relative (half a unit of
    /// the 12th digit): the file writes each value in its unit to 12 significant digits
    /// (`domain::rounding`, README), and nothing finer.
    #[test]
    fn parameter_sets_round_trip(d in prop::collection::vec(-1e-3..1e-3f64, 43)) {
        let mut set = ParameterSet::nominal(irb120(), Tool::flange(), [0.1, -0.2, 0.3, 0.4, -0.5, 0.6]);
        for (v, dv) in set.values.iter_mut().zip(&d) {
            *v += dv;
        }
        let back = ParameterSetDoc::from_json(&ParameterSetDoc::new(set.clone()).to_json_pretty()).unwrap().set;
        for (a, b) in back.values.iter().zip(&set.values) {
            prop_assert!((a - b).abs() <= 5e-12 * b.abs() + 1e-300, "{} vs {}", a, b);
        }
        let (a, b) = (back.value(Param::Base(3)).unwrap(), set.value(Param::Base(3)).unwrap());
        prop_assert!((a - b).abs() < 1e-11, "base rotation {} vs {}", a, b);
    }

    /// TriCal readings → ball centre inverts the tip simulation anywhere in a ±1 mm cube.
    #[test]
    fn trical_round_trip(x in -1e-3..1e-3f64, y in -1e-3..1e-3f64, z in -1e-3..1e-3f64) {
        let tc = TriCal::default();
        let c = nalgebra::Vector3::new(x, y, z);
        let back = tc.centre(tc.readings(&c).unwrap()).unwrap();
        prop_assert!((back - c).norm() < 1e-14);
    }

    /// The CLI-facing parsers never panic on arbitrary JSON-ish text.
    #[test]
    fn parameter_parser_never_panics(s in ".{0,200}") {
        let _ = ParameterSetDoc::from_json(&s);
    }
}

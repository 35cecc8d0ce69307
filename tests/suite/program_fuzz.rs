//! Program parsers under mutation: the example programs of each language with random byte edits
//! (deletions, insertions of syntax characters, digits, letters, line breaks, ISO-8859-1 bytes,
//! replacements) must be read and filtered into `Ok` or an error naming a line — never a panic, and
//! within a time bound. The tests' generated programs (arrays, `MoveC`, FOLDs, `FRAME` tools, joint
//! positions, a second motion group, `movec`, `pose_trans`, …) are mutated too, with whole tokens
//! of each language spliced in. `PROPTEST_CASES=5000 cargo test --release --test suite program_fuzz::` runs
//! longer.

use crate::programs;

use std::time::{Duration, Instant};

use proptest::prelude::*;
use proptest::test_runner::Config;
use robocal::domain::ParameterSetDoc;
use robocal::domain::program::{
    AngleOrder, Calibration, FilterError, FilterOptions, GivenFrames, JointTargets, ProgramFile, filter, read,
};
use robocal::kinematics::Compensator;

fn config(default: u32) -> Config {
    let cases = std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(default);
    Config { cases, failure_persistence: None, ..Config::default() }
}

const BOUND: Duration = Duration::from_secs(5);

/// The example programs, one set of files per language.
fn programs() -> Vec<Vec<(&'static str, &'static [u8])>> {
    vec![
        vec![("weld.mod", include_bytes!("../../examples/programs/weld.mod"))],
        vec![
            ("weld.src", include_bytes!("../../examples/programs/weld.src")),
            ("weld.dat", include_bytes!("../../examples/programs/weld.dat")),
        ],
        vec![("weld.ls", include_bytes!("../../examples/programs/weld.ls"))],
        vec![("pick.script", include_bytes!("../../examples/programs/pick.script"))],
    ]
}

/// An edit at a position (taken modulo the file's length).
#[derive(Clone, Debug)]
enum Edit {
    Delete(usize, usize),
    Insert(usize, Vec<u8>),
    Replace(usize, u8),
}

fn edit() -> impl Strategy<Value = Edit> {
    let byte = prop_oneof![
        Just(b'['),
        Just(b']'),
        Just(b'{'),
        Just(b'}'),
        Just(b','),
        Just(b';'),
        Just(b'"'),
        Just(b'\''),
        Just(b'!'),
        Just(b'#'),
        Just(b':'),
        Just(b'='),
        Just(b'-'),
        Just(b'.'),
        Just(b'\n'),
        Just(b'\r'),
        Just(b'E'),
        Just(b'9'),
        Just(b'0'),
        Just(b' '),
        Just(0xDF),
        Just(0xFF),
        Just(0),
    ];
    prop_oneof![
        (any::<usize>(), 1usize..40).prop_map(|(a, n)| Edit::Delete(a, n)),
        (any::<usize>(), prop::collection::vec(byte.clone(), 1..6)).prop_map(|(a, b)| Edit::Insert(a, b)),
        (any::<usize>(), byte).prop_map(|(a, b)| Edit::Replace(a, b)),
    ]
}

/// Edits that splice in whole tokens of the four languages (keywords, numbers at the edges of
/// what parses, half aggregates) as well as single bytes.
fn token_edit() -> impl Strategy<Value = Edit> {
    let token = prop_oneof![
        Just(&b"MoveL "[..]),
        Just(&b"MoveC "[..]),
        Just(&b"\\WObj:="[..]),
        Just(&b"CONST robtarget q:="[..]),
        Just(&b"[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"[..]),
        Just(&b"DECL E6POS XQ={X 1,Y 2}"[..]),
        Just(&b"LIN "[..]),
        Just(&b"$TOOL=TOOL_DATA[7]"[..]),
        Just(&b"BASE_NO "[..]),
        Just(&b"S 'B111'"[..]),
        Just(&b"P[9]{"[..]),
        Just(&b"GP1:"[..]),
        Just(&b"CONFIG : 'F D B, 9, -9, 0',"[..]),
        Just(&b"UF : 9"[..]),
        Just(&b"J1="[..]),
        Just(&b"movel(p["[..]),
        Just(&b"movej(["[..]),
        Just(&b"set_tcp(p[0,0,"[..]),
        Just(&b"1E400"[..]),
        Just(&b"-1e-320"[..]),
        Just(&b"0.0000000000000000000001"[..]),
        Just(&b"99999999999999999999"[..]),
        Just(&b"NaN"[..]),
        Just(&b"inf"[..]),
        Just(&b"{"[..]),
        Just(&b"}"[..]),
        Just(&b"]"[..]),
        Just(&b"\r\n"[..]),
    ];
    prop_oneof![edit(), (any::<usize>(), token).prop_map(|(a, t)| Edit::Insert(a, t.to_vec())),]
}

fn mutate(bytes: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    for e in edits {
        let n = b.len().max(1);
        match e {
            Edit::Delete(a, k) => {
                let s = a % n;
                let e = (s + k).min(b.len());
                if s < e {
                    b.drain(s..e);
                }
            }
            Edit::Insert(a, x) => {
                let s = a % (b.len() + 1);
                b.splice(s..s, x.iter().copied());
            }
            Edit::Replace(a, x) => {
                if !b.is_empty() {
                    let s = a % b.len();
                    b[s] = *x;
                }
            }
        }
    }
    b
}

proptest! {
    #![proptest_config(config(64))]

    #[test]
    fn mutated_programs_read_and_filter_without_panicking(lang in 0usize..4, which in 0usize..2, edits in prop::collection::vec(edit(), 1..8)) {
        let doc = ParameterSetDoc::from_json(include_str!("../../examples/irb120_table_5_1.json")).unwrap();
        let comp = Compensator::new(&doc.set);
        let cal = Calibration { set: &doc.set, compensator: &comp, envelope: None, allow_outside_envelope: false, covariance: None, held_out: None };
        let mut frames = GivenFrames::default();
        frames.add_tool("1:30,0,210,0,45,0", AngleOrder::Abc, "tool").unwrap();
        frames.add_base("2:400,-100,60,30,0,0", AngleOrder::Abc, "base").unwrap();
        let opts = FilterOptions {
            joint_targets: JointTargets::Recompute,
            frames,
            seed_joints: Some(vec![0.0, -1.5, 1.5, -1.5, 1.5, 0.0]),
            ..Default::default()
        };
        let files: Vec<ProgramFile> = programs()[lang]
            .iter()
            .enumerate()
            .map(|(k, (name, bytes))| ProgramFile {
                name: name.to_string(),
                bytes: if k == which % 2 { mutate(bytes, &edits) } else { bytes.to_vec() },
            })
            .collect();
        let t0 = Instant::now();
        match read(&files, &opts) {
            Ok(_) | Err(FilterError::Input(_)) => {}
            Err(FilterError::Program(e)) => prop_assert!(!e.message.is_empty()),
        }
        match filter(&cal, &files, &opts) {
            Ok(out) => prop_assert_eq!(out.files.len(), files.len()),
            Err(FilterError::Program(e)) => prop_assert!(e.line > 0 || e.message.contains("no /"), "{}", e),
            Err(FilterError::Input(_)) => {}
        }
        prop_assert!(t0.elapsed() < BOUND, "{:?}", t0.elapsed());
    }
}

fn generated(lang: usize) -> programs::Sample {
    match lang {
        0 => programs::rapid(7, 24),
        1 => programs::krl(7, 24),
        2 => programs::fanuc(7, 24),
        _ => programs::urscript(7, 24),
    }
}

proptest! {
    #![proptest_config(config(48))]

    #[test]
    fn mutated_generated_programs_filter_without_panicking(lang in 0usize..4, which in 0usize..2, edits in prop::collection::vec(token_edit(), 1..10)) {
        let sample = generated(lang);
        let set = if lang == 3 { programs::ur10_set() } else { programs::irb120_set() };
        let comp = Compensator::new(&set);
        let cal = Calibration { set: &set, compensator: &comp, envelope: None, allow_outside_envelope: false, covariance: None, held_out: None };
        let opts = FilterOptions {
            joint_targets: if which == 0 { JointTargets::Recompute } else { JointTargets::Keep },
            frames: sample.frames.clone(),
            seed_joints: sample.seed_joints.clone(),
            ..Default::default()
        };
        let n = sample.files.len();
        let files: Vec<ProgramFile> = sample
            .files
            .iter()
            .enumerate()
            .map(|(k, f)| ProgramFile {
                name: f.name.clone(),
                bytes: if k == which % n { mutate(&f.bytes, &edits) } else { f.bytes.clone() },
            })
            .collect();
        let t0 = Instant::now();
        match filter(&cal, &files, &opts) {
            Ok(out) => prop_assert_eq!(out.files.len(), files.len()),
            Err(FilterError::Program(e)) => prop_assert!(e.line > 0 || e.message.contains("no /"), "{}", e),
            Err(FilterError::Input(_)) => {}
        }
        prop_assert!(t0.elapsed() < BOUND, "{:?}", t0.elapsed());
    }
}

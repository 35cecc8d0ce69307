//! Structure-aware fuzzing of the file and wire parsers in `src/domain/` (cell files, CSV
//! measurement batches, robot models, parameter sets, compensation targets): valid documents,
//! mutated — fields removed, values of the wrong type, huge, negative-zero and non-finite
//! numbers, huge arrays, deep nesting, unicode — must give `Ok` or an error, never a panic, and
//! within a time bound. Default case counts keep each property to a few seconds in `cargo test`;
//! `PROPTEST_CASES=5000 cargo test --release --test suite fuzz_parsers::` runs longer.

use std::sync::LazyLock;
use std::time::{Duration, Instant};

use proptest::prelude::*;
use proptest::test_runner::Config;
use robocal::domain::cell::{cell_to_json, parse_cell};
use robocal::domain::measurement_csv::parse_csv;
use robocal::domain::{ParameterSetDoc, RobotSpec, TargetSpec};
use serde_json::{Value, json};

/// Cases per property: PROPTEST_CASES when set, else `default`.
fn config(default: u32) -> Config {
    let cases = std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(default);
    Config { cases, failure_persistence: None, ..Config::default() }
}

/// How long one parse may take on the largest mutated document (an unoptimised build, a
/// machine shared with other builds: generous; a hang or a quadratic blow-up still exceeds it).
const PARSE_BOUND: Duration = Duration::from_secs(5);

/// A small valid cell file from the virtual cell (3 candidates per ball, 3 tracker poses).
static CELL: LazyLock<Value> = LazyLock::new(|| {
    let opts = robocal::sim::simulate::SimulateOptions { id_per_ball: 3, validation: 3, ..Default::default() };
    let sim = robocal::sim::simulate::simulate(&opts).expect("the virtual cell simulates");
    serde_json::from_str(&cell_to_json(&sim.cell)).unwrap()
});

fn parameter_set() -> Value {
    serde_json::from_str(include_str!("../../examples/irb120_table_5_1.json")).unwrap()
}

fn targets() -> Value {
    serde_json::from_str(include_str!("../../examples/targets.json")).unwrap()
}

/// A custom robot (a planar 2R arm with a wrist), valid.
fn custom_robot() -> Value {
    json!({"name": "arm", "convention": "modified", "gravity_mps2": [0.0, 0.0, -9.81], "joints": [
        {"alpha_deg": 0.0, "a_mm": 0.0, "d_mm": 290.0, "limits_deg": [-165.0, 165.0], "mass_kg": 3.0, "com_mm": [0.0, 0.0, -50.0]},
        {"alpha_deg": -90.0, "a_mm": 0.0, "d_mm": 0.0, "theta_deg": -90.0, "limits_deg": [-110.0, 110.0]},
        {"alpha_deg": 0.0, "a_mm": 270.0, "d_mm": 0.0, "beta_deg": 0.0, "limits_deg": [-110.0, 70.0]}
    ]})
}

/// One mutation of a JSON document, at the node `at` picks (an index into its nodes, modulo).
#[derive(Clone, Debug)]
enum Mutation {
    Remove,
    Replace(Value),
    /// An array's first element repeated `n` times.
    Grow(usize),
    /// The node wrapped in `depth` arrays.
    Nest(usize),
}

fn weird_value() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        Just(json!(1e308)),
        Just(json!(-1e308)),
        Just(json!(f64::MIN_POSITIVE)),
        Just(json!(-0.0)),
        Just(json!(u64::MAX)),
        Just(json!(i64::MIN)),
        Just(json!(4_294_967_296_u64)),
        Just(json!("NaN")),
        Just(json!("inf")),
        Just(json!([])),
        Just(json!({})),
        any::<f64>().prop_filter("finite", |x| x.is_finite()).prop_map(|x| json!(x)),
        any::<i64>().prop_map(|x| json!(x)),
        "\\PC{0,40}".prop_map(Value::String),
        prop::collection::vec(any::<f64>().prop_filter("finite", |x| x.is_finite()), 0..8).prop_map(|v| json!(v)),
    ]
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        2 => Just(Mutation::Remove),
        5 => weird_value().prop_map(Mutation::Replace),
        1 => (1usize..20_000).prop_map(Mutation::Grow),
        1 => (1usize..300).prop_map(Mutation::Nest),
    ]
}

/// Number of nodes of a document (itself included).
fn count(v: &Value) -> usize {
    1 + match v {
        Value::Array(a) => a.iter().map(count).sum(),
        Value::Object(o) => o.values().map(count).sum(),
        _ => 0,
    }
}

/// Apply `m` at the `k`-th node in pre-order; `true` when applied.
fn apply(v: &mut Value, k: &mut usize, m: &Mutation) -> bool {
    if *k == 0 {
        match m {
            Mutation::Remove | Mutation::Replace(_) => {}
            Mutation::Grow(n) => {
                if let Value::Array(a) = v
                    && let Some(first) = a.first().cloned()
                {
                    a.resize(*n, first);
                    return true;
                }
            }
            Mutation::Nest(depth) => {
                let mut inner = v.take();
                for _ in 0..*depth {
                    inner = Value::Array(vec![inner]);
                }
                *v = inner;
                return true;
            }
        }
        if let Mutation::Replace(x) = m {
            *v = x.clone();
            return true;
        }
        return false; // Remove is applied by the parent
    }
    *k -= 1;
    match v {
        Value::Array(a) => {
            for i in 0..a.len() {
                if *k == 0 && matches!(m, Mutation::Remove) {
                    a.remove(i);
                    return true;
                }
                if apply(&mut a[i], k, m) {
                    return true;
                }
            }
        }
        Value::Object(o) => {
            let keys: Vec<String> = o.keys().cloned().collect();
            for key in keys {
                if *k == 0 && matches!(m, Mutation::Remove) {
                    o.remove(&key);
                    return true;
                }
                if apply(o.get_mut(&key).unwrap(), k, m) {
                    return true;
                }
            }
        }
        _ => {}
    }
    false
}

/// A valid document with up to three mutations applied at random nodes.
fn mutated(doc: Value) -> impl Strategy<Value = Value> {
    prop::collection::vec((any::<prop::sample::Index>(), mutation()), 0..4).prop_map(move |ms| {
        let mut d = doc.clone();
        for (at, m) in ms {
            let mut k = at.index(count(&d));
            apply(&mut d, &mut k, &m);
        }
        d
    })
}

/// Run `f` and check it returns within the bound (a panic fails the property by itself).
fn bounded<T>(what: &str, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    assert!(t.elapsed() < PARSE_BOUND, "{what} took {:?}", t.elapsed());
    out
}

proptest! {
    #![proptest_config(config(48))]

    #[test]
    fn cell_files_never_panic(doc in mutated(CELL.clone())) {
        let text = doc.to_string();
        let _ = bounded("parse_cell", || parse_cell(&text));
    }

    #[test]
    fn parameter_sets_never_panic(doc in mutated(parameter_set())) {
        let text = doc.to_string();
        let _ = bounded("parameter set", || ParameterSetDoc::from_json(&text));
    }

    #[test]
    fn robot_models_never_panic(doc in mutated(custom_robot())) {
        let _ = bounded("robot model", || RobotSpec::from_json_value(&doc).and_then(|r| r.to_model()));
    }

    #[test]
    fn targets_never_panic(doc in mutated(targets())) {
        let text = doc.to_string();
        bounded("targets", || {
            if let Ok(v) = serde_json::from_str::<Value>(&text)
                && let Some(list) = v.get("targets").and_then(Value::as_array)
            {
                for t in list {
                    if let Ok(spec) = serde_json::from_value::<TargetSpec>(t.clone()) {
                        let _ = spec.to_target(6);
                    }
                }
            }
        });
    }
}

/// CSV: a valid batch, then rows and cells mutated (removed, emptied, replaced by odd numbers,
/// unicode, quotes), extra and missing columns, a huge field.
fn csv_valid() -> (Vec<String>, Vec<Vec<String>>) {
    let header: Vec<String> = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,ball,dx_mm,dy_mm,dz_mm,time_s,sequence"
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = (0..5)
        .map(|i| {
            let f = i as f64;
            vec![
                format!("{}", 10.0 + f),
                "-20.5".into(),
                "30".into(),
                "0".into(),
                "45".into(),
                format!("{}", -f),
                format!("{}", 1 + i % 3),
                "0.01".into(),
                "-0.02".into(),
                "0.003".into(),
                format!("{}", 2.5 * f),
                format!("{i}"),
            ]
        })
        .collect();
    (header, rows)
}

fn csv_cell() -> impl Strategy<Value = String> {
    prop_oneof![
        Just(String::new()),
        Just("NaN".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("1e309".to_string()),
        Just("-0".to_string()),
        Just("18446744073709551616".to_string()),
        Just("\"".to_string()),
        Just("x".repeat(100_000)),
        any::<f64>().prop_map(|x| x.to_string()),
        any::<i64>().prop_map(|x| x.to_string()),
        "\\PC{0,20}",
    ]
}

proptest! {
    #![proptest_config(config(96))]

    #[test]
    fn csv_batches_never_panic(
        edits in prop::collection::vec((0usize..6, 0usize..13, csv_cell()), 0..6),
        drop_col in prop::option::of(0usize..12),
        extra_rows in 0usize..3000,
        dof in prop_oneof![Just(6usize), Just(7), Just(0), Just(1)],
    ) {
        let (mut header, mut rows) = csv_valid();
        for (r, c, value) in edits {
            match rows.get_mut(r) {
                Some(row) if c < row.len() => row[c] = value,
                Some(row) => row.push(value),
                None => header.push(value),
            }
        }
        if let Some(c) = drop_col {
            header.remove(c.min(header.len() - 1));
        }
        let first = rows[0].clone();
        rows.extend(std::iter::repeat_n(first, extra_rows));
        let mut text = header.join(",");
        for row in &rows {
            text.push('\n');
            text.push_str(&row.join(","));
        }
        let _ = bounded("parse_csv", || parse_csv(text.as_bytes(), dof));
    }
}

/// The generators make what they claim: the unmutated documents parse, so the mutations start
/// from valid input (a fuzzer of invalid documents only would never reach the deeper checks).
#[test]
fn the_seed_documents_are_valid() {
    parse_cell(&CELL.to_string()).expect("cell");
    ParameterSetDoc::from_json(&parameter_set().to_string()).expect("parameter set");
    RobotSpec::from_json_value(&custom_robot()).and_then(|r| r.to_model()).expect("robot");
    for t in targets()["targets"].as_array().unwrap() {
        serde_json::from_value::<TargetSpec>(t.clone()).unwrap().to_target(6).expect("target");
    }
    let (header, rows) = csv_valid();
    let text = std::iter::once(header.join(",")).chain(rows.iter().map(|r| r.join(","))).collect::<Vec<_>>().join("\n");
    assert_eq!(parse_csv(text.as_bytes(), 6).expect("csv").len(), 5);
}

/// Deep nesting is refused by the JSON reader's recursion limit, not by a stack overflow.
#[test]
fn deep_nesting_is_an_error_not_a_stack_overflow() {
    let depth = 100_000;
    let text = format!("{}{}", "[".repeat(depth), "]".repeat(depth));
    assert!(parse_cell(&text).is_err());
    assert!(ParameterSetDoc::from_json(&text).is_err());
    let obj = format!("{}1{}", "{\"robot\":".repeat(depth), "}".repeat(depth));
    assert!(parse_cell(&obj).is_err());
}

/// A huge declared count is refused before anything of that size is allocated: the work bounds
/// of `domain::limits` (per-ball candidates, validation poses) answer at once for any count, and
/// a target's seed of a billion joints is never materialised (the JSON holds what it holds).
#[test]
fn huge_declared_counts_do_not_allocate() {
    use robocal::domain::limits;
    let t = Instant::now();
    for n in [usize::MAX, 1 << 40, limits::MAX_PER_BALL + 1] {
        assert!(limits::per_ball(n, "per_ball").is_err());
    }
    for n in [usize::MAX, 1 << 40, limits::MAX_VALIDATION + 1] {
        assert!(limits::validation(n, "validation").is_err());
    }
    // A planning request declaring 2^64−1 poses: refused by its bounds, in microseconds.
    assert!(t.elapsed() < Duration::from_millis(50));
    // Seed joints for a 6-joint robot, 100,000 of them: refused, naming the field.
    let spec: TargetSpec = serde_json::from_value(json!({
        "position_mm": [300.0, 0.0, 400.0], "rotation_deg": [0.0, 180.0, 0.0],
        "seed_joints_deg": vec![0.0; 100_000]
    }))
    .unwrap();
    let e = spec.to_target(6).unwrap_err();
    assert!(e.path.contains("seed_joints_deg"), "{e}");
}

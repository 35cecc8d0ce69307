//! The diagnosis proven on withheld effects (`robocal bench-diagnosis`): in the virtual cell,
//! each effect of the simulator is put in the true robot and withheld from the model, with and
//! without the auxiliary logs (temperature, approach); the no-effect case and the
//! out-of-library link bending are added; every case runs over several seeds. Each diagnosis is
//! scored against what an honest answer is:
//!
//! | case | expected |
//! |---|---|
//! | a separable effect | `named`, the right kind first, the right joint (and harmonic) |
//! | no effect | `none` (anything else is a false alarm) |
//! | a payload error with one payload; backlash with neither approach log nor measuring order | `not_separable` (never a confident name) |
//! | link bending | `unknown_effect`, `not_separable` or `partial`, never `named` |
//! | thermal growth without a temperature log | anything but a confident wrong name |
//!
//! and the gap closure of the named model against the oracle's (the true effect's terms added).

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use crate::cell::Cell;
use crate::diagnose::library::Kind;
use crate::diagnose::{DiagnoseOptions, Input, Status, diagnose, heldout_with};
use crate::identify::{IdentifyOptions, ModelOptions, identify};
use crate::kinematics::{JointTerm, Param};
use crate::sim::effects::Effects;
use crate::sim::simulate::{SimulateOptions, simulate};

/// What an honest diagnosis of a case says.
#[derive(Clone, Debug, PartialEq)]
pub enum Expect {
    /// `named`, with this kind first; the joint (0-based) and harmonic in quarters when given.
    Named {
        kind: Kind,
        joint: Option<usize>,
        from: Option<usize>,
        quarters: Option<u16>,
    },
    None,
    NotSeparable,
    /// `unknown_effect`, `not_separable` or `partial` (never a confident name).
    NotNamed,
    /// Anything but a name of another effect (an effect whose log is missing).
    NoWrongName,
    /// No confident name: anything but `named` (`partial` included).
    NoName,
}

/// One case of the suite.
#[derive(Clone, Debug)]
pub struct Case {
    pub name: String,
    /// `simulate --effects` specification.
    pub effects: String,
    /// Keep the temperature and approach logs.
    pub aux: bool,
    /// Shuffle each session's measurements, drop their times and sequence numbers and mark the
    /// sessions shuffled (measuring order lost).
    pub shuffle: bool,
    pub noise: NoiseVariant,
    /// Validate with a heavier tool (the thesis's 2.7 kg artefact tool, set-up 3): a second payload.
    pub heavy_validation: bool,
    /// Where the data come from: the thesis's lab, or a realistic twin of a real tracker run.
    pub rig: Rig,
    pub expect: Expect,
}

/// The measuring set-up of a case.
#[derive(Clone, Debug, PartialEq)]
pub enum Rig {
    /// The virtual cell of the thesis's lab: TriCal on three balls, tracker validation poses.
    Lab,
    /// A realistic twin of a real tracker run ([`crate::sim::tracker_run`]): three SMRs on a
    /// plate, random workspace poses in measuring order, written as three-reflector files and
    /// imported as a user would (payload unknown), with a random turn of every joint at every
    /// stop (`jitter_deg`, 1σ per joint: an error that changes from pose to pose and that no
    /// term explains) and `removed` rows deleted afterwards.
    /// `stop_s` seconds from stop to stop: with a thermal effect, the robot warms up along the
    /// run, which the files do not log.
    TrackerTwin { jitter_deg: f64, removed: usize, payload_kg: f64, stop_s: f64 },
}

/// How the virtual cell's instruments are simulated (the diagnosis's own instrument model
/// stays the default: a cell measured differently than assumed must not raise false alarms).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoiseVariant {
    /// The centring loop, a 16 µm + 0.8 µm/m tracker (the instrument model's assumption).
    Default,
    /// The TriCal's pessimistic shortcut: the TCP uniform in the ε-ball.
    UniformBall,
    /// A tracker 50 % noisier than the instrument model assumes.
    NoisyTracker,
}

/// The result of one case and seed.
#[derive(Clone, Debug)]
pub struct Outcome {
    pub case: String,
    pub seed: u64,
    pub status: Status,
    /// Label of the first effect of the verdict (named or suspected).
    pub first: Option<String>,
    /// The verdict's one-sentence summary.
    pub summary: String,
    pub correct: bool,
    /// The named kind is another effect than the one withheld.
    pub wrong_name: bool,
    pub heldout_mean: f64,
    pub floor_mean: f64,
    /// Held-out mean of the last accepted model and of the oracle, m.
    pub final_mean: f64,
    pub oracle_mean: Option<f64>,
    /// Gap closure of the diagnosis's model relative to the oracle's.
    pub closure_ratio: Option<f64>,
    /// The first round's best confirmed candidate's share of what a smooth function of the
    /// configuration explains, and whether it lies inside the smoother's span (the data the
    /// `partial` threshold is chosen on).
    pub share: Option<(f64, bool)>,
    /// That candidate's gap closure on the RMS (what `name_closure` is compared with).
    pub closure: Option<f64>,
    pub seconds: f64,
    pub error: Option<String>,
}

/// The suite: every effect of the simulator withheld in turn (magnitudes whose contribution
/// after calibration stands above the floor), with and without logs, plus the special cases.
pub fn suite() -> Vec<Case> {
    let named = |kind, joint: Option<usize>, from: Option<usize>, quarters: Option<u16>| Expect::Named {
        kind,
        joint,
        from,
        quarters,
    };
    let mut cases = Vec::new();
    let both = |cases: &mut Vec<Case>, name: &str, effects: &str, with: Expect, without: Expect| {
        cases.push(Case {
            name: name.to_string(),
            effects: effects.into(),
            aux: true,
            shuffle: false,
            noise: NoiseVariant::Default,
            heavy_validation: false,
            rig: Rig::Lab,
            expect: with,
        });
        cases.push(Case {
            name: format!("{name} (no logs)"),
            effects: effects.into(),
            aux: false,
            shuffle: false,
            noise: NoiseVariant::Default,
            heavy_validation: false,
            rig: Rig::Lab,
            expect: without,
        });
    };
    both(&mut cases, "none", "", Expect::None, Expect::None);
    for (name, noise) in [
        ("none (uniform-ball centring)", NoiseVariant::UniformBall),
        ("none (tracker +50 %)", NoiseVariant::NoisyTracker),
    ] {
        cases.push(Case {
            name: name.into(),
            effects: String::new(),
            aux: true,
            shuffle: false,
            noise,
            heavy_validation: false,
            rig: Rig::Lab,
            expect: Expect::None,
        });
    }
    let cyc = named(Kind::Cyclic, Some(2), None, Some(8));
    both(&mut cases, "cyclic j3 h2", "cyclic:j=3:h=2:amp_deg=0.01", cyc.clone(), cyc);
    let cyc = named(Kind::Cyclic, Some(0), None, Some(4));
    both(&mut cases, "cyclic j1 h1", "cyclic:j=1:h=1:amp_deg=0.01", cyc.clone(), cyc);
    let cyc = named(Kind::Cyclic, Some(4), None, Some(4));
    both(&mut cases, "cyclic j5 h1", "cyclic:j=5:h=1:amp_deg=0.02", cyc.clone(), cyc);
    let cyc = named(Kind::Cyclic, Some(5), None, Some(8));
    both(&mut cases, "cyclic j6 h2", "cyclic:j=6:h=2:amp_deg=0.05", cyc.clone(), cyc);
    let cyc = named(Kind::Cyclic, Some(3), None, Some(4 * 17));
    both(&mut cases, "cyclic j4 h17 (gear mesh)", "cyclic:j=4:h=17:amp_deg=0.02", cyc.clone(), cyc);
    let cyc = named(Kind::Cyclic, Some(1), None, Some(4 * 23));
    both(&mut cases, "cyclic j2 h23", "cyclic:j=2:h=23:amp_deg=0.006", cyc.clone(), cyc);
    let bl = named(Kind::Backlash, Some(1), None, None);
    both(&mut cases, "backlash j2", "backlash:j=2:deg=0.01", bl.clone(), bl);
    let bl = named(Kind::Backlash, Some(2), None, None);
    both(&mut cases, "backlash j3", "backlash:j=3:deg=0.008", bl.clone(), bl);
    cases.push(Case {
        name: "backlash j2 (no logs, shuffled)".into(),
        effects: "backlash:j=2:deg=0.01".into(),
        aux: false,
        shuffle: true,
        noise: NoiseVariant::Default,
        heavy_validation: false,
        rig: Rig::Lab,
        expect: Expect::NotSeparable,
    });
    both(&mut cases, "thermal", "thermal", named(Kind::Thermal, None, None, None), Expect::NoWrongName);
    let cp = named(Kind::Coupling, Some(5), Some(4), None);
    both(&mut cases, "coupling 5→6", "coupling:from=5:to=6:ratio=0.001", cp.clone(), cp);
    let cp = named(Kind::Coupling, Some(3), Some(2), None);
    both(&mut cases, "coupling 3→4", "coupling:from=3:to=4:ratio=0.0005", cp.clone(), cp);
    let cc = named(Kind::ComplianceCubic, Some(1), None, None);
    both(&mut cases, "compliance_cubic j2", "compliance_cubic:j=2:d=2.5e-7", cc.clone(), cc);
    let cc = named(Kind::ComplianceCubic, Some(2), None, None);
    both(&mut cases, "compliance_cubic j3", "compliance_cubic:j=3:d=2e-5", cc.clone(), cc);
    both(&mut cases, "tool_mass (one payload)", "tool_mass:delta_kg=0.5", Expect::NotSeparable, Expect::NotSeparable);
    cases.push(Case {
        name: "tool_mass (2.7 kg validation tool)".into(),
        effects: "tool_mass:delta_kg=0.5".into(),
        aux: true,
        shuffle: false,
        noise: NoiseVariant::Default,
        heavy_validation: true,
        rig: Rig::Lab,
        expect: named(Kind::ToolMass, None, None, None),
    });
    cases.push(Case {
        name: "none (2.7 kg validation tool)".into(),
        effects: String::new(),
        aux: true,
        shuffle: false,
        noise: NoiseVariant::Default,
        heavy_validation: true,
        rig: Rig::Lab,
        expect: Expect::None,
    });
    both(&mut cases, "link_bending", "link_bending:deg_per_nm=0.00286", Expect::NotNamed, Expect::NotNamed);
    let hb = named(Kind::HayatiBeta, Some(2), None, None);
    both(&mut cases, "-beta", "no_beta", hb.clone(), hb);
    let cm = named(Kind::Compliance, None, None, None);
    both(&mut cases, "-compliance", "no_compliance", cm.clone(), cm);
    // Out-of-library effects too weak for the smoother to stand out (issue 24): a look-alike
    // may take a share of them, never a confident name.
    for (name, k) in [("link_bending (weak, 0.1 mm)", 0.00057), ("link_bending (very weak, 0.04 mm)", 0.00025)] {
        cases.push(Case {
            name: name.into(),
            effects: format!("link_bending:deg_per_nm={k}"),
            aux: true,
            shuffle: false,
            noise: NoiseVariant::Default,
            heavy_validation: false,
            rig: Rig::Lab,
            expect: Expect::NoName,
        });
    }
    // Realistic twins of a real tracker run: the payload unknown, an error from pose to pose of
    // 0.1–0.3 mm that no term explains, rows removed; the hysteresis is named from the order of
    // the rows, the random part left unexplained.
    // One twin warms up by 8 °C over its 2.7 hours (a stop every 10 s), unlogged: a drift along
    // the measuring order that no term can take, beside the hysteresis that is named.
    let twin = |jitter_deg: f64, stop_s: f64| Rig::TrackerTwin { jitter_deg, removed: 10, payload_kg: 1.0, stop_s };
    for (name, effects, jitter, stop_s, expect) in [
        (
            "twin: hysteresis j1–j3, jitter 0.1 mm",
            "backlash:j=1:deg=0.006,backlash:j=2:deg=0.006,backlash:j=3:deg=0.006",
            0.006,
            0.0,
            named(Kind::Backlash, None, None, None),
        ),
        (
            "twin: hysteresis j2, jitter 0.2 mm",
            "backlash:j=2:deg=0.01",
            0.012,
            0.0,
            named(Kind::Backlash, Some(1), None, None),
        ),
        (
            "twin: hysteresis j2, unlogged warm-up",
            "thermal,backlash:j=2:deg=0.01",
            0.012,
            10.0,
            named(Kind::Backlash, Some(1), None, None),
        ),
        ("twin: no hysteresis, jitter 0.2 mm", "", 0.012, 0.0, Expect::NoName),
    ] {
        cases.push(Case {
            name: name.into(),
            effects: effects.into(),
            aux: true,
            shuffle: false,
            noise: NoiseVariant::Default,
            heavy_validation: false,
            rig: twin(jitter, stop_s),
            expect,
        });
    }
    // A term the model lacks leaks into the undeclared payload, which the identification then
    // holds at 0 kg; once the coupling is named the data determine it, and the diagnosis adopts it
    // when held-out poses confirm it (its final figure can then pass the oracle's, which keeps the
    // payload held).
    cases.push(Case {
        name: "twin: coupling 2→3, undeclared 2.3 kg plate".into(),
        effects: "coupling:from=2:to=3:ratio=0.002".into(),
        aux: true,
        shuffle: false,
        noise: NoiseVariant::Default,
        heavy_validation: false,
        rig: Rig::TrackerTwin { jitter_deg: 0.0075, removed: 10, payload_kg: 2.3, stop_s: 0.0 },
        expect: named(Kind::Coupling, Some(2), Some(1), None),
    });
    cases
}

/// The true effect's model terms (the oracle), when the library has them.
fn oracle_terms(e: &Effects) -> Option<Vec<Param>> {
    let mut p = Vec::new();
    for c in &e.cyclic {
        let j = c.j - 1;
        p.push(Param::Joint(j, JointTerm::Cyclic { harmonic: c.h, cosine: false }));
        p.push(Param::Joint(j, JointTerm::Cyclic { harmonic: c.h, cosine: true }));
    }
    for b in &e.backlash {
        p.push(Param::Joint(b.j - 1, JointTerm::Backlash));
    }
    if e.thermal.is_some() {
        p.push(Param::Thermal);
    }
    for c in &e.coupling {
        p.push(Param::Joint(c.to - 1, JointTerm::Coupling { from: c.from - 1 }));
    }
    for c in &e.compliance_cubic {
        p.push(Param::Joint(c.j - 1, JointTerm::ComplianceCubic));
    }
    if e.tool_mass.is_some() {
        p.push(Param::ToolMass);
    }
    if e.no_beta {
        p.push(Param::Beta(2));
    }
    if e.no_compliance {
        p.extend((1..6).map(|j| Param::Joint(j, JointTerm::Compliance)));
    }
    if e.link_bending.is_some() || p.is_empty() { None } else { Some(p) }
}

/// The cell a case's diagnosis sees: logs stripped, order shuffled (and marked so).
fn prepare_cell(mut cell: Cell, case: &Case, seed: u64) -> Cell {
    for s in &mut cell.sessions {
        for m in &mut s.measurements {
            if !case.aux {
                m.temperature_c = None;
                m.approach = None;
            }
            if case.shuffle {
                m.time_s = None;
                m.sequence = None;
            }
        }
        if case.shuffle {
            s.measurements.shuffle(&mut ChaCha8Rng::seed_from_u64(seed ^ 0x5348_5546));
            s.order = crate::cell::MeasuringOrder::Shuffled;
        }
    }
    cell
}

/// Run one case at one seed.
pub fn run_case(case: &Case, seed: u64, opts: &DiagnoseOptions) -> Outcome {
    let t0 = std::time::Instant::now();
    let fail = |e: String| failed(case, seed, t0, e);
    let effects = match Effects::parse(&case.effects, 6) {
        Ok(e) => e,
        Err(e) => return fail(e.to_string()),
    };
    let mut noise = crate::sim::instruments::Noise::default();
    match case.noise {
        NoiseVariant::Default => {}
        NoiseVariant::UniformBall => noise.centring = crate::sim::instruments::Centring::UniformBall,
        NoiseVariant::NoisyTracker => {
            noise.tracker_sigma *= 1.5;
            noise.tracker_sigma_per_m *= 1.5;
        }
    }
    if let Rig::TrackerTwin { jitter_deg, removed, payload_kg, stop_s } = case.rig {
        return match twin_cell(&effects, jitter_deg, removed, payload_kg, stop_s, seed) {
            Ok(cell) => score(case, seed, &cell, &effects, ModelOptions::default(), opts, t0),
            Err(e) => fail(e),
        };
    }
    let validation_payload = case.heavy_validation.then(|| (2.7, nalgebra::Vector3::new(0.050, 0.025, 0.100)));
    let sim = match simulate(&SimulateOptions {
        seed,
        effects: effects.clone(),
        noise,
        validation_payload,
        ..SimulateOptions::default()
    }) {
        Ok(s) => s,
        Err(e) => return fail(e.to_string()),
    };
    let cell = prepare_cell(sim.cell, case, seed);
    let model = ModelOptions { beta: !effects.no_beta, compliance: !effects.no_compliance, ..ModelOptions::default() };
    score(case, seed, &cell, &effects, model, opts, t0)
}

/// A realistic twin's cell: the run written as three-reflector files and imported as a user
/// would, payload unknown.
fn twin_cell(
    effects: &Effects,
    jitter_deg: f64,
    removed: usize,
    payload_kg: f64,
    stop_s: f64,
    seed: u64,
) -> Result<Cell, String> {
    use crate::sim::tracker_run::{TrackerRunOptions, tracker_run};
    let o = TrackerRunOptions {
        seed,
        removed,
        payload_kg,
        effects: effects.clone(),
        jitter: jitter_deg * crate::units::DEG,
        stop_s,
        ..TrackerRunOptions::default()
    };
    let run = tracker_run(&o).map_err(|e| e.to_string())?;
    static RUNS: AtomicUsize = AtomicUsize::new(0);
    let k = RUNS.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("robocal-twin-{}-{seed}-{k}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let written = run.write(&dir, "run", 6).map_err(|e| e.to_string());
    let imported = written.and_then(|(j, f)| {
        crate::import::three_reflector::import(
            &j,
            &f,
            crate::kinematics::model::irb120(),
            crate::cell::Purpose::Identification,
        )
        .map_err(|e| e.to_string())
    });
    let _ = std::fs::remove_dir_all(&dir);
    Ok(imported?.cell)
}

/// The outcome of a run that could not be scored, and why.
fn failed(case: &Case, seed: u64, t0: std::time::Instant, e: String) -> Outcome {
    Outcome {
        case: case.name.clone(),
        seed,
        status: Status::None,
        first: None,
        summary: String::new(),
        correct: false,
        wrong_name: false,
        heldout_mean: f64::NAN,
        floor_mean: f64::NAN,
        final_mean: f64::NAN,
        oracle_mean: None,
        closure_ratio: None,
        share: None,
        closure: None,
        seconds: t0.elapsed().as_secs_f64(),
        error: Some(e),
    }
}

/// Identify `model` on the case's cell, diagnose it, and score the verdict.
fn score(
    case: &Case,
    seed: u64,
    cell: &Cell,
    effects: &Effects,
    model: ModelOptions,
    opts: &DiagnoseOptions,
    t0: std::time::Instant,
) -> Outcome {
    let fail = |e: String| failed(case, seed, t0, e);
    // The calibration the engineer has: the model without the withheld effect, identified on
    // the identification sessions.
    let id = match identify(cell, &IdentifyOptions { model, ..IdentifyOptions::default() }) {
        Ok(id) => id,
        Err(e) => return fail(format!("identification: {e}")),
    };
    let identified: Vec<bool> = id.status.iter().map(|s| *s == crate::identify::Status::Identified).collect();
    let input = Input { cell, set: &id.set, identified: Some(identified), fixed: Vec::new(), excluded: Vec::new() };
    let o = DiagnoseOptions { seed, ..opts.clone() };
    let d = match diagnose(&input, &o) {
        Ok(d) => d,
        Err(e) => return fail(e.to_string()),
    };
    let v = &d.verdict;
    let first = v.effects.first().map(|e| e.candidate.clone());
    let withheld_kinds = withheld_kinds(effects);
    let wrong_name = v.status == Status::Named && first.as_ref().is_some_and(|c| !withheld_kinds.contains(&c.kind));
    let correct = match &case.expect {
        Expect::Named { kind, joint, from, quarters } => {
            v.status == Status::Named
                && first.as_ref().is_some_and(|c| {
                    c.kind == *kind
                        && (joint.is_none() || c.joint == *joint)
                        && (from.is_none() || c.from == *from)
                        && (quarters.is_none() || c.quarters == *quarters)
                })
        }
        Expect::None => v.status == Status::None,
        Expect::NotSeparable => v.status == Status::NotSeparable,
        Expect::NotNamed => matches!(v.status, Status::NotSeparable | Status::UnknownEffect | Status::Partial),
        Expect::NoWrongName => !wrong_name,
        Expect::NoName => v.status != Status::Named,
    };
    let heldout_mean = d.decomposition.heldout.mean;
    let floor_mean = d.decomposition.floor.mean;
    let final_mean = d.shrink.last().map_or(heldout_mean, |s| s.stats.mean);
    let oracle_mean = oracle_terms(effects).and_then(|t| heldout_with(&input, &o, &t).ok()).map(|s| s.mean);
    let closure_ratio = oracle_mean.and_then(|om| {
        let oracle = heldout_mean - om;
        (oracle > 0.0).then(|| (heldout_mean - final_mean) / oracle)
    });
    Outcome {
        case: case.name.clone(),
        seed,
        status: v.status,
        first: first.map(|c| c.label()),
        summary: v.summary.clone(),
        correct,
        wrong_name,
        heldout_mean,
        floor_mean,
        final_mean,
        oracle_mean,
        closure_ratio,
        share: d.rounds.first().and_then(|r| r.share),
        closure: d.rounds.first().and_then(|r| r.closure),
        seconds: t0.elapsed().as_secs_f64(),
        error: None,
    }
}

/// The kinds that name the withheld effect correctly (for the wrong-name count).
fn withheld_kinds(e: &Effects) -> Vec<Kind> {
    let mut k = Vec::new();
    if !e.cyclic.is_empty() {
        k.extend([Kind::Cyclic, Kind::JointMap]);
    }
    if !e.backlash.is_empty() {
        k.push(Kind::Backlash);
    }
    if e.thermal.is_some() {
        k.push(Kind::Thermal);
    }
    if !e.coupling.is_empty() {
        k.push(Kind::Coupling);
    }
    if !e.compliance_cubic.is_empty() {
        k.push(Kind::ComplianceCubic);
    }
    if e.tool_mass.is_some() {
        k.push(Kind::ToolMass);
    }
    if e.no_beta {
        k.push(Kind::HayatiBeta);
    }
    if e.no_compliance {
        k.push(Kind::Compliance);
    }
    k
}

/// Run `cases` × `seeds` on `threads` threads; results in (case, seed) order. `progress` is
/// called after each run with (done, total).
pub fn run_suite(
    cases: &[Case],
    seeds: &[u64],
    opts: &DiagnoseOptions,
    threads: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<Outcome> {
    let jobs: Vec<(usize, u64)> = (0..cases.len()).flat_map(|c| seeds.iter().map(move |&s| (c, s))).collect();
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<Outcome>>> = Mutex::new(vec![None; jobs.len()]);
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, jobs.len().max(1)) {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&(c, s)) = jobs.get(k) else { break };
                    let r = run_case(&cases[c], s, opts);
                    out.lock().expect("no panic while holding the lock")[k] = Some(r);
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, jobs.len());
                }
            });
        }
    });
    out.into_inner().expect("joined").into_iter().map(|o| o.expect("every job ran")).collect()
}

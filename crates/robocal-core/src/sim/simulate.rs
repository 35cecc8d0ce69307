//! `robocal simulate`: plan the measuring runs of the virtual cell, measure the true robot along
//! them, and return the cell file and the truth behind it.

use super::effects::Effects;
use super::instruments::Noise;
use super::measure::{BallPose, MeasureError, NestPose, Rig, RunTruth, measure};
use super::poses::{CellLayout, PlanError, PlanningCell, plan_identification, plan_validation};
use super::truth::Truth;
use crate::cell::Cell;
use crate::kinematics::Tool;
use crate::kinematics::thesis::irb120_table_5_1;

/// Everything a simulation depends on. `Default` is the thesis's cell and robot with default
/// noise, no effects, 120 poses per ball and 506 validation poses, seed 1.
#[derive(Clone, Debug)]
pub struct SimulateOptions {
    /// Seeds the identification plan, the validation plan (ChaCha8, each from this seed) and the
    /// measuring run (its own stream of the same seed): same options, same cell.
    pub seed: u64,
    /// The lab: robot model, base guess, tool and nests, artefact, tracker, home.
    pub layout: CellLayout,
    /// The truth; `None` = the thesis's identified IRB 120 (Table 5.1) carrying the layout's
    /// tool, with `effects` attached (whatever robot the layout names). A given truth must be of
    /// the layout's robot (same preset and number of joints) and is used as it is.
    pub truth: Option<Truth>,
    /// Effects attached to the default truth; ignored when `truth` is given.
    pub effects: Effects,
    /// Identification configurations per ball (three balls, measured ball by ball).
    pub id_per_ball: usize,
    /// Validation configurations (tracker stops).
    pub validation: usize,
    /// Instrument and robot noise.
    pub noise: Noise,
    /// Record the TriCal's indicator readings left after centring in each identification
    /// measurement.
    pub record_indicators: bool,
    /// The payload of the validation run's tool when it is not the TriCal's: (mass kg, centre of
    /// mass in the flange frame, m) — the thesis's set-up 3 validated with the 2.7 kg artefact
    /// tool (Table 3.4) after identifying with the 1.7 kg TriCal. The reflector nests stay.
    pub validation_payload: Option<(f64, nalgebra::Vector3<f64>)>,
    /// Read every validation pose on each nest that faces the tracker with a clear line of sight
    /// (in nest order), not only on the best-facing one: with nests that open the same way
    /// ([`reflector_plate`](super::poses::reflector_plate)) the nests' sessions share their poses.
    pub all_nests: bool,
}

impl Default for SimulateOptions {
    fn default() -> Self {
        Self {
            seed: 1,
            layout: CellLayout::default(),
            truth: None,
            effects: Effects::default(),
            id_per_ball: 120,
            validation: 506,
            noise: Noise::default(),
            record_indicators: false,
            validation_payload: None,
            all_nests: false,
        }
    }
}

/// A simulated cell and its truth.
#[derive(Clone, Debug)]
pub struct Simulated {
    /// The cell file's content: the nominal model, base guess, artefact and the measured
    /// sessions (see [`measure`]).
    pub cell: Cell,
    /// The true robot that was measured.
    pub truth: Truth,
    /// What really happened at each measurement.
    pub run: RunTruth,
}

/// Why a simulation failed.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    /// The layout cannot be planned in, or too few poses were found.
    #[error("planning: {0}")]
    Plan(#[from] PlanError),
    /// The measuring run failed.
    #[error("measuring: {0}")]
    Measure(#[from] MeasureError),
    /// The given truth is not of the layout's robot.
    #[error("truth: {0}")]
    Truth(String),
}

/// Simulate the virtual cell: plan `id_per_ball` identification configurations on each ball and
/// `validation` tracker configurations on the layout (nominal model, base guess), then measure
/// the true robot along them with the TriCal and the laser tracker. Deterministic for
/// [`SimulateOptions::seed`]. [`simulate_with_progress`] without the reports.
pub fn simulate(opts: &SimulateOptions) -> Result<Simulated, SimulateError> {
    simulate_with_progress(opts, &|_, _, _| {})
}

/// The stages of [`simulate`], for progress reports.
pub const SIMULATE_STAGES: usize = 3;

/// [`simulate`], calling `progress` with (stages done, [`SIMULATE_STAGES`], the next stage) as it
/// goes: planning the ball poses, planning the tracker poses, measuring; then once more with
/// (3, 3, `done`).
pub fn simulate_with_progress(
    opts: &SimulateOptions,
    progress: &dyn Fn(usize, usize, &str),
) -> Result<Simulated, SimulateError> {
    let layout = &opts.layout;
    progress(0, SIMULATE_STAGES, "planning ball poses");
    let truth = match &opts.truth {
        Some(t) => {
            if t.set.model.links.len() != layout.robot.links.len() || t.set.model.preset != layout.robot.preset {
                return Err(SimulateError::Truth(format!(
                    "the cell layout is built for robot '{}', the truth is robot '{}'",
                    layout.robot.name, t.set.model.name
                )));
            }
            t.clone()
        }
        None => Truth::new(irb120_table_5_1(layout.tool.clone()), opts.effects.clone()),
    };
    let balls: Vec<BallPose> = plan_identification(layout, opts.id_per_ball, opts.seed)?
        .iter()
        .map(|p| BallPose { q: p.q, ball: p.ball.expect("identification poses have a ball") })
        .collect();
    progress(1, SIMULATE_STAGES, "planning tracker poses");
    let planned = plan_validation(layout, opts.validation, opts.seed)?;
    progress(2, SIMULATE_STAGES, "measuring");
    let nests: Vec<NestPose> = if opts.all_nests {
        let pc = PlanningCell::new(layout)?;
        planned.iter().flat_map(|p| pc.visible_nests(&p.q).into_iter().map(|nest| NestPose { q: p.q, nest })).collect()
    } else {
        planned.iter().map(|p| NestPose { q: p.q, nest: p.nest.expect("validation poses have a nest") }).collect()
    };
    let nest_tools: Vec<Tool> = layout
        .nests
        .iter()
        .map(|n| {
            let mut t = n.tool.clone();
            if let Some((mass, com)) = opts.validation_payload {
                t.mass = mass;
                t.com = com;
            }
            t
        })
        .collect();
    let rig = Rig {
        model: &layout.robot,
        base_guess: layout.base,
        artefact: &layout.artefact,
        trical: &layout.tool,
        nests: &nest_tools,
        tracker_in_base: layout.tracker,
        noise: opts.noise.clone(),
        record_indicators: opts.record_indicators,
    };
    let (cell, run) = measure(&truth, &rig, &layout.home, &balls, &nests, opts.seed)?;
    progress(3, SIMULATE_STAGES, "done");
    Ok(Simulated { cell, truth, run })
}

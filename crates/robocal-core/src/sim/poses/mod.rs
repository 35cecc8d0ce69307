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
//! - Validation: configurations drawn in Cartesian space (by default, the thesis's way: the TCP
//!   uniform in a box, a nest turned towards the tracker) or uniformly within the joint limits,
//!   kept when a reflector nest faces the tracker with a clear line of sight.
//!
//! Every accepted configuration passes the static check of [`CollisionModel`] and the path check
//! of the linear joint move from the previously accepted one (the first from the home
//! configuration), so the list is a runnable measuring sequence in its order.
//!
//! # Files
//! `layout` (the lab: [`CellLayout`] and its compilation into a [`PlanningCell`]),
//! `identification` (draws on the balls), `validation` (draws facing the tracker) and `sequence`
//! (a collision-free order for a given set, and the path check of a sequence). This file holds
//! what they share: the planned pose, the plan and its statistics, the errors.

mod identification;
mod layout;
mod sequence;
mod validation;

use nalgebra::Vector3;
use rand::Rng;

pub use identification::IdentificationOptions;
pub use layout::{CellLayout, Nest, reflector_plate, trical_nests};
pub use validation::{ValidationOptions, ValidationSampling};

use super::collision::{Collision, CollisionModel};
use crate::kinematics::{AnalyticIk, Branch, Chain, Frame};

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
    /// The layout (or a planning option) cannot be planned with; the message says why.
    #[error("cell layout: {0}")]
    Layout(String),
    /// The home configuration fails the static collision check.
    #[error("the home configuration is not collision-free: {0}")]
    Home(Collision),
    /// Identification: a ball ran out of draws before enough configurations were accepted.
    #[error("ball {ball}: found only {found} of {wanted} identification poses in {attempts} attempts")]
    Ball {
        /// The ball, 1-based.
        ball: usize,
        /// Configurations accepted.
        found: usize,
        /// Configurations asked for.
        wanted: usize,
        /// Draws made.
        attempts: usize,
    },
    /// Validation: the draws ran out before enough configurations were accepted.
    #[error("found only {found} of {wanted} validation poses in {attempts} attempts")]
    Validation {
        /// Configurations accepted.
        found: usize,
        /// Configurations asked for.
        wanted: usize,
        /// Draws made.
        attempts: usize,
    },
    /// Sequencing: no collision-free move reaches any configuration left, and none can be
    /// slotted in between sequenced ones.
    #[error(
        "no collision-free move leads to any of the {remaining} configurations left after {sequenced} were sequenced"
    )]
    Sequence {
        /// Configurations in order so far.
        sequenced: usize,
        /// Configurations left over.
        remaining: usize,
    },
}

/// What happened to the draws of a plan (for one ball, or for the validation plan).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PlanStats {
    /// Draws made; each ends in exactly one of the counts below.
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
    /// Accepted into the plan.
    pub accepted: usize,
}

/// A plan with its statistics: one [`PlanStats`] per ball for identification, one in all for
/// validation.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The configurations, in measuring order.
    pub poses: Vec<PlannedPose>,
    /// The draws' statistics: per ball (balls 1, 2, 3) or one for validation.
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
    /// The layout it was compiled from.
    pub fn layout(&self) -> &CellLayout {
        &self.layout
    }

    /// The nominal chain with the measuring tool, on the base guess.
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// The analytic inverse kinematics of that chain.
    pub fn ik(&self) -> &AnalyticIk {
        &self.ik
    }

    /// The collision model: the robot's capsules on the nominal chain with the measuring tool's
    /// shape, the table and the artefact's plate.
    pub fn collision(&self) -> &CollisionModel {
        &self.collision
    }

    /// The tracker in {W} (the layout's position in {0} moved by the base guess), m.
    pub fn tracker(&self) -> Vector3<f64> {
        self.tracker
    }

    /// One of the inverse-kinematics branches that reach `target` within the joint limits, drawn
    /// at random (one draw from `rng`, none when no branch reaches it).
    fn random_branch<R: Rng>(&self, target: &Frame, rng: &mut R) -> Result<[f64; 6], Reject> {
        let mut solutions = [[0.0; 6]; 8];
        let mut n = 0;
        for b in Branch::ALL {
            if let Ok(q) = self.ik.solve(target, b) {
                solutions[n] = q;
                n += 1;
            }
        }
        if n == 0 {
            return Err(Reject::Unreachable);
        }
        Ok(solutions[rng.random_range(0..n)])
    }
}

#[cfg(test)]
impl PlanningCell {
    /// The thesis cell ([`CellLayout::default`]) compiled, for the tests.
    fn thesis() -> Self {
        Self::new(&CellLayout::default()).expect("the default layout compiles")
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
/// of the three balls, in measuring order (ball 1's, then 2's, then 3's). Compiles the layout
/// ([`PlanningCell::new`]) and runs [`PlanningCell::plan_identification`] with the other
/// [`IdentificationOptions`] defaults; their errors are passed on.
pub fn plan_identification(layout: &CellLayout, per_ball: usize, seed: u64) -> Result<Vec<PlannedPose>, PlanError> {
    let opts = IdentificationOptions { per_ball, ..Default::default() };
    Ok(PlanningCell::new(layout)?.plan_identification(&opts, seed)?.poses)
}

/// Validation plan of a layout: `count` configurations in measuring order, each with its nest.
/// Compiles the layout ([`PlanningCell::new`]) and runs [`PlanningCell::plan_validation`] with
/// the other [`ValidationOptions`] defaults (Cartesian sampling); their errors are passed on.
pub fn plan_validation(layout: &CellLayout, count: usize, seed: u64) -> Result<Vec<PlannedPose>, PlanError> {
    let opts = ValidationOptions { count, ..Default::default() };
    Ok(PlanningCell::new(layout)?.plan_validation(&opts, seed)?.poses)
}

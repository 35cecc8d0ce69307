//! Pure kinematics: the MDH + Hayati model, its parameter vector, forward kinematics, the exact
//! identification Jacobian, gravity torques, analytic and numerical inverse kinematics, and
//! fake-target compensation. SI units throughout (m, rad, kg, N·m).

pub(crate) mod chain;
pub mod compensate;
pub mod frame;
pub(crate) mod gravity;
pub mod ik_analytic;
pub mod ik_numeric;
pub mod model;
pub(crate) mod param_set;
pub mod params;
pub mod thesis;

pub use chain::{Chain, JointState, Rows, Trace};
pub use compensate::{Compensated, Compensator, Seed};
pub use frame::Frame;
pub use gravity::GravityModel;
pub use ik_analytic::{AnalyticIk, Branch, Confdata, IkError, Singularity};
pub use ik_numeric::{IkOptions, IkSolution};
pub use model::{Link, MAX_JOINTS, Preset, RobotModel, Tool};
pub use param_set::ParameterSet;
pub use params::{JointTerm, Param, ParamLayout, Unit};

//! A robot model, its tool and one value for every parameter: what identification produces, what
//! compensation consumes, and what the parameter-set JSON files carry.

use super::chain::{Chain, JointState};
use super::frame::Frame;
use super::gravity::GravityModel;
use super::model::{RobotModel, Tool};
use super::params::{Param, ParamLayout};

/// A robot model, its declared tool, and the nominal and current value of every parameter of its
/// layout (SI units).
#[derive(Clone, Debug, PartialEq)]
pub struct ParameterSet {
    /// The nominal robot structure.
    pub model: RobotModel,
    /// The tool as declared (its TCP is the nominal of `tool_x` … `tool_c`; its payload drives the
    /// gravity torques).
    pub tool: Tool,
    /// The parameters, in the order of `nominal` and `values`.
    pub layout: ParamLayout,
    /// Nominal value of each parameter (SI).
    pub nominal: Vec<f64>,
    /// Current value of each parameter (SI).
    pub values: Vec<f64>,
}

impl ParameterSet {
    /// The nominal parameter set of a model with a tool and a base pose χ (m, rad).
    pub fn nominal(model: RobotModel, tool: Tool, base: [f64; 6]) -> Self {
        let layout = ParamLayout::full(&model);
        let nominal = layout.nominal_values(&model, &tool, &base);
        Self { values: nominal.clone(), nominal, layout, model, tool }
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.model.dof()
    }

    /// Current value of `p` (SI); `None` when the layout has no such parameter.
    pub fn value(&self, p: Param) -> Option<f64> {
        self.layout.index_of(p).map(|i| self.values[i])
    }

    /// Nominal value of `p` (SI); `None` when the layout has no such parameter.
    #[cfg(test)]
    pub(crate) fn nominal_value(&self, p: Param) -> Option<f64> {
        self.layout.index_of(p).map(|i| self.nominal[i])
    }

    /// Attach further parameters (effect terms) with nominal and value zero; returns their
    /// indices. Parameters already present keep their values.
    pub fn extend(&mut self, extra: &[Param]) -> Vec<usize> {
        let before = self.layout.len();
        let idx = self.layout.extend(extra);
        let added = self.layout.len() - before;
        self.nominal.extend(std::iter::repeat_n(0.0, added));
        self.values.extend(std::iter::repeat_n(0.0, added));
        idx
    }

    /// Set a parameter's value; false when the model has no such parameter.
    pub fn set(&mut self, p: Param, v: f64) -> bool {
        match self.layout.index_of(p) {
            Some(i) => {
                self.values[i] = v;
                true
            }
            None => false,
        }
    }

    /// The same set with another tool: its TCP becomes the tool parameters' value and nominal
    /// (a tool the identification did not see is taken as declared), and its payload drives the
    /// gravity torques.
    pub fn with_tool(&self, tool: Tool) -> ParameterSet {
        let mut s = self.clone();
        for k in 0..6 {
            if let Some(i) = s.layout.index_of(Param::Tool(k)) {
                s.values[i] = tool.tcp[k];
                s.nominal[i] = tool.tcp[k];
            }
        }
        s.tool = tool;
        s
    }

    /// The chain at the current values.
    pub fn chain(&self) -> Chain {
        Chain::new(&self.model, &self.layout, &self.values)
    }

    /// The chain at the nominal values: the controller's model.
    pub fn nominal_chain(&self) -> Chain {
        Chain::new(&self.model, &self.layout, &self.nominal)
    }

    /// Gravity torques of this robot carrying this tool's payload (nominal geometry).
    pub fn gravity(&self) -> GravityModel {
        self.gravity_for(&self.tool)
    }

    /// Gravity torques of this robot carrying another tool's payload. A `tool_mass` parameter (an
    /// identified payload error, accepted from a diagnosis) is added to the tool's declared mass
    /// here, once: the torques a parameter set's FK, validation and compensation use are those of
    /// the true payload. So is a first-moment error (`tool_moment_*`, the payload's centre of
    /// mass identified with it).
    pub fn gravity_for(&self, tool: &Tool) -> GravityModel {
        let mut t = tool.clone();
        t.mass += self.value(Param::ToolMass).unwrap_or(0.0);
        let mut g = GravityModel::new(&self.model, &t);
        let h: [f64; 3] = std::array::from_fn(|k| self.value(Param::ToolMoment(k)).unwrap_or(0.0));
        if h != [0.0; 3] {
            g.add_payload_moment(&nalgebra::Vector3::from(h));
        }
        g
    }

    /// Pose vector χ of a block (`Param::Base` or `Param::Tool`) at the current values.
    pub fn pose_of(&self, block: fn(usize) -> Param) -> [f64; 6] {
        let mut chi = [0.0; 6];
        for (k, v) in chi.iter_mut().enumerate() {
            *v = self.value(block(k)).unwrap_or(0.0);
        }
        chi
    }

    /// Convenience: T_T^W at joint readings q (rad), torques computed here. Batch callers should
    /// build the [`Chain`] and [`GravityModel`] once instead.
    pub fn fk(&self, q: &[f64]) -> Frame {
        let tau = self.gravity().torques(q);
        self.chain().fk(&JointState::with_torques(q, &tau[..self.dof()]))
    }
}

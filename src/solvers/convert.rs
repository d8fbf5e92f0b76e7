//! A policy of one control mode run in another: the scripted solvers drive the end effector
//! (or joint positions), and [`ModeConverted`] turns their actions into the env's mode, as
//! ManiSkill's `replay_trajectory --target-control-mode` converts demos, but closed loop. It
//! is how solver demonstrations are recorded in a joint mode (docs/solvers.md, "In another
//! control mode"), e.g. Fetch's in `pd_joint_delta_pos`, which ManiSkill can build where it
//! cannot build Fetch's end-effector modes.
use super::{Policy, SolverError};
use crate::env::{make, Env, EnvConfig, ObsMode};

/// A policy in its own control mode driving an env of another mode of the same robot. Every
/// step a shadow env in the policy's mode takes the env's state ([`Env::sync_from`]), the
/// policy acts on the shadow, the shadow steps, and the env's action is the one that sets the
/// joint targets the shadow's controller set ([`Env::convert_action`]: shared parts such as
/// the gripper copied, joint position parts inverted, deltas clipped to the mode's bounds).
/// Where no delta is clipped, the env takes the targets the policy's mode would have taken.
#[derive(Debug)]
pub struct ModeConverted {
    inner: Box<dyn Policy>,
    shadow: Env,
    native: Vec<f32>,
    /// The policy's own mode (the shadow's).
    mode: String,
}

impl ModeConverted {
    /// Wraps the policy that `build` makes for an env of `env`'s pair in `mode`.
    pub fn new(
        env: &Env,
        mode: &str,
        build: impl FnOnce(&Env) -> Result<Box<dyn Policy>, SolverError>,
    ) -> Result<ModeConverted, SolverError> {
        let refuse = |why: String| SolverError::WrongControlMode {
            robot: env.robot_spec().uid(),
            required: mode.to_string(),
            mode: env.control_mode().to_string(),
            why,
        };
        let config = EnvConfig {
            control_mode: Some(mode.to_string()),
            obs_mode: ObsMode::State,
            ..env.config().clone()
        };
        let shadow = make(env.id(), config).map_err(|e| refuse(e.to_string()))?;
        let inner = build(&shadow)?;
        let native = vec![0.0; shadow.action_space().shape[0]];
        // Refused now (not at the first step) when a part can be neither copied nor inverted.
        let mut out = vec![0.0; env.action_space().shape[0]];
        env.convert_action(&shadow, &native, &mut out)
            .map_err(|e| refuse(e.to_string()))?;
        Ok(ModeConverted {
            inner,
            shadow,
            native,
            mode: mode.to_string(),
        })
    }
}

impl Policy for ModeConverted {
    fn reset(&mut self, env: &Env) {
        if self.shadow.sync_from(env).is_ok() {
            self.inner.reset(&self.shadow);
        }
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        if self.try_act(env, action).is_err() {
            action.fill(0.0);
        }
    }

    fn try_act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), SolverError> {
        let fail = |e: crate::env::EnvError| SolverError::WrongControlMode {
            robot: env.robot_spec().uid(),
            required: self.mode.clone(),
            mode: env.control_mode().to_string(),
            why: e.to_string(),
        };
        self.shadow.sync_from(env).map_err(fail)?;
        self.inner.try_act(&self.shadow, &mut self.native)?;
        self.shadow.step(&self.native).map_err(fail)?;
        env.convert_action(&self.shadow, &self.native, action)
            .map_err(fail)
    }
}

//! A policy of one control mode run in another: the scripted solvers drive the end effector
//! (or joint positions), and [`ModeConverted`] turns their actions into the env's mode, as
//! ManiSkill's `replay_trajectory --target-control-mode` converts demos, but closed loop. It
//! is how solver demonstrations are recorded in a joint mode (docs/solvers.md, "In another
//! control mode"), e.g. Fetch's in `pd_joint_delta_pos`, which ManiSkill can build where it
//! cannot build Fetch's end-effector modes.
use super::{Policy, SolverError};
use crate::env::{make, Env, EnvConfig, ObsMode};

/// The same env in another control mode, kept on an env's state: a policy acts on it in its
/// own mode, and the env gets the action of its mode that sets the joint targets the shadow's
/// controller set ([`Env::sync_from`], [`Env::convert_action`]). Used by [`ModeConverted`]
/// and by solvers that set some joint targets themselves (the Fetch's LiftPegUpright roll).
#[derive(Debug)]
pub(crate) struct Shadow {
    /// The shadow env ...
    pub env: Env,
    /// ... and its action, written by the policy that drives it.
    pub action: Vec<f32>,
    /// The shadow's mode.
    mode: String,
}

impl Shadow {
    /// `env`'s env and robot in `mode` (state observations).
    pub fn new(env: &Env, mode: &str) -> Result<Shadow, SolverError> {
        let config = EnvConfig {
            control_mode: Some(mode.to_string()),
            obs_mode: ObsMode::State,
            ..env.config().clone()
        };
        let shadow = make(env.id(), config).map_err(|e| refusal(env, mode, e.to_string()))?;
        let action = vec![0.0; shadow.action_space().shape[0]];
        Ok(Shadow {
            env: shadow,
            action,
            mode: mode.to_string(),
        })
    }

    /// Takes `env`'s state.
    pub fn sync(&mut self, env: &Env) -> Result<(), SolverError> {
        self.env
            .sync_from(env)
            .map_err(|e| refusal(env, &self.mode, e.to_string()))
    }

    /// Steps the shadow with [`Shadow::action`] and writes `env`'s action that sets the
    /// same joint targets into `out`.
    pub fn step_into(&mut self, env: &Env, out: &mut [f32]) -> Result<(), SolverError> {
        let fail = |e: crate::env::EnvError| refusal(env, &self.mode, e.to_string());
        self.env.step(&self.action).map_err(fail)?;
        env.convert_action(&self.env, &self.action, out)
            .map_err(fail)
    }
}

/// The refusal of a policy in `mode` to drive `env`.
fn refusal(env: &Env, mode: &str, why: String) -> SolverError {
    SolverError::WrongControlMode {
        robot: env.robot_spec().uid(),
        required: mode.to_string(),
        mode: env.control_mode().to_string(),
        why,
    }
}

/// A policy in its own control mode driving an env of another mode of the same robot. Every
/// step a shadow env in the policy's mode takes the env's state ([`Env::sync_from`]), the
/// policy acts on the shadow, the shadow steps, and the env's action is the one that sets the
/// joint targets the shadow's controller set ([`Env::convert_action`]: shared parts such as
/// the gripper copied, joint position parts inverted, deltas clipped to the mode's bounds).
/// Where no delta is clipped, the env takes the targets the policy's mode would have taken.
#[derive(Debug)]
pub struct ModeConverted {
    inner: Box<dyn Policy>,
    shadow: Shadow,
}

impl ModeConverted {
    /// Wraps the policy that `build` makes for an env of `env`'s pair in `mode`.
    pub fn new(
        env: &Env,
        mode: &str,
        build: impl FnOnce(&Env) -> Result<Box<dyn Policy>, SolverError>,
    ) -> Result<ModeConverted, SolverError> {
        let shadow = Shadow::new(env, mode)?;
        let inner = build(&shadow.env)?;
        // Refused now (not at the first step) when a part can be neither copied nor inverted.
        let mut out = vec![0.0; env.action_space().shape[0]];
        env.convert_action(&shadow.env, &shadow.action, &mut out)
            .map_err(|e| refusal(env, mode, e.to_string()))?;
        Ok(ModeConverted { inner, shadow })
    }
}

impl Policy for ModeConverted {
    fn reset(&mut self, env: &Env) {
        if self.shadow.sync(env).is_ok() {
            self.inner.reset(&self.shadow.env);
        }
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        if self.try_act(env, action).is_err() {
            action.fill(0.0);
        }
    }

    fn try_act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), SolverError> {
        self.shadow.sync(env)?;
        self.inner
            .try_act(&self.shadow.env, &mut self.shadow.action)?;
        self.shadow.step_into(env, action)
    }
}

//! The gymnasium-style env API: [`make`], [`Env::reset`], [`Env::step`], spaces, the
//! registry, and exact ManiSkill seeding ([`crate::rng`]).
//!
//! Semantics follow ManiSkill3's single-env CPU path (docs/env.md): 20 Hz control, `terminated` =
//! success, `truncated` once `elapsed_steps ≥ max_episode_steps` (50), and the env keeps
//! running after either — nothing stops further `step` calls (`elapsed_steps` keeps
//! counting, `truncated` stays true), exactly as upstream.
mod cameras;
pub mod checks;
mod config;
mod convert;
mod memory;
mod registry;
pub mod render;
mod segmentation;
pub mod state_dict;
mod types;
pub mod vec;
pub use config::{
    EnvConfig, EnvError, ObsMode, PinchSolver, RewardMode, SimConfig, Textures, CONSTRUCTION_SEED,
    CONTROL_FREQ, DEFAULT_QPOS_NOISE, MAX_EPISODE_STEPS,
};
pub use registry::{default_robot, registry, scene_mjcf, EnvId, EnvInfo};
pub use render::{depth_to_mm, CameraImage, PointCloud};
pub use state_dict::{ActionPart, DriveTargets, StateDict, StateDictError};
pub use types::{BoxSpace, EnvState, Info, Step};
pub use vec::{EnvLabeller, RolloutBuffers, VecEnv, VecPolicy, MAX_POLICY_STEP};

use std::sync::Arc;

use crate::controllers::{Controller, Drives};
use crate::mujoco::{Data, Model, Warnings};
use crate::obs::ObsWriter;
use crate::rng::{NumpyRandomState, TorchGenerator};
use crate::robots::{RobotIds, RobotSpec, TableScene};
use crate::tasks::{finger_forces, Task, TaskCtx};
use registry::{build_scene, env_spec, resolve_robot};

/// The simulation state an env steps: the robot in its scene, its controller and drives,
/// the task, and the per-step joint readings the task evaluates. Kept apart from the step
/// outputs ([`Env`]'s `obs` and `info`) so that one [`TaskCtx`] borrowed from it can feed
/// `evaluate`, the observation and the reward while those are written.
#[derive(Debug)]
struct Sim {
    spec: &'static RobotSpec,
    /// The physics state, and through it the model it steps (edited in place at the resets of
    /// a task whose shapes change every episode).
    data: Data,
    robot: RobotIds,
    controller: Controller,
    /// The robot's joint drives (targets and force law).
    drives: Drives,
    task: Box<dyn Task>,
    /// Contact forces on the two grasp fingers from the grasp object (last substep).
    finger_forces: [[f64; 3]; 2],
    /// Robot qpos and qvel (ManiSkill order) of the current state.
    qpos: Vec<f64>,
    qvel: Vec<f64>,
}

impl Sim {
    /// Reads the robot's joint positions and velocities of the current state.
    fn read_joints(&mut self) {
        self.robot.joints.qpos(&self.data, &mut self.qpos);
        self.robot.joints.qvel(&self.data, &mut self.qvel);
        self.drives.report_velocities(&self.data, &mut self.qvel);
    }

    /// Writes the flat observation (docs/env.md §7.3): `agent/qpos`, `agent/qvel`, the
    /// controller state, then the task's extras (`privileged`: the state-only keys too).
    fn observe(&self, ctx: &TaskCtx, info: &[f64], privileged: bool, out: &mut ObsWriter) {
        out.set_prefix("agent/");
        out.put("qpos", self.qpos.iter().copied());
        out.put("qvel", self.qvel.iter().copied());
        out.set_prefix("agent/controller/");
        self.controller.observe(out);
        out.set_prefix("extra/");
        self.task.observe_extra(ctx, info, privileged, out);
    }

    /// What the task reads in one evaluation (after [`Sim::read_joints`]).
    fn ctx(&self) -> TaskCtx<'_> {
        let (tcp_pos, tcp_quat) = self.robot.tcp_pose(&self.data);
        TaskCtx {
            data: &self.data,
            robot: &self.robot,
            spec: self.spec,
            tcp_pos,
            tcp_quat,
            qpos: &self.qpos,
            qvel: &self.qvel,
            finger_forces: &self.finger_forces,
        }
    }
}

/// Hands the steps in which the gripper pinches the task's object to PhysX's step replica
/// ([`PinchSolver::PhysxTgs`]); errors say why the robot or task cannot take it.
fn enable_pinch_replica(
    model: &Model,
    drives: &mut Drives,
    rs: &RobotSpec,
    env: &str,
    object: crate::mujoco::BodyId,
) -> Result<(), EnvError> {
    let unsupported = |reason: String| EnvError::PinchSolverUnsupported {
        env: env.to_string(),
        robot: rs.uid().to_string(),
        reason,
    };
    let parts = rs
        .convex_parts(model)
        .map_err(unsupported)?
        .ok_or_else(|| {
            unsupported(format!(
                "the robot ships no models/{}/{} (robots with convex parts: so100, {})",
                rs.uid(),
                crate::robots::CONVEX_PARTS_FILE,
                crate::robots::BOX_FINGER_ROBOTS.join(", ")
            ))
        })?;
    let body = object.index();
    let geom = (0..model.ngeom())
        .find(|&g| {
            model.geom_bodyid()[g] as usize == body
                && crate::controllers::tgs::OBJECT_GEOM_TYPES.contains(&model.geom_type()[g])
        })
        .ok_or_else(|| {
            unsupported("the task's object is neither a box nor a sphere".to_string())
        })?;
    drives
        .enable_pinch_replica(model, parts, body, geom)
        .map_err(unsupported)
}

/// Gives a sphere object's geoms PhysX's contact offset as MuJoCo margin and gap, so that
/// MuJoCo's collision reports the sphere's contacts with the scene before they touch and the
/// pinch replica solves them as PhysX's speculative contacts (a sphere released onto the bin's
/// wall edge, docs/physics.md, "The pinch in PhysX's step"). MuJoCo's own step gives them no
/// force (`Drives::step`). Box objects are left as they are: MuJoCo's box–box collider picks
/// other touching points when given a margin.
fn speculative_sphere_contacts(
    model: &mut Arc<Model>,
    object: crate::mujoco::BodyId,
) -> Result<(), EnvError> {
    let body = object.index();
    let spheres: Vec<usize> = (0..model.ngeom())
        .filter(|&g| {
            model.geom_bodyid()[g] as usize == body
                && model.geom_type()[g] == crate::mujoco::GEOM_SPHERE
        })
        .collect();
    if spheres.is_empty() {
        return Ok(());
    }
    let m = Arc::make_mut(model);
    let offset = crate::controllers::tgs::CONTACT_OFFSET;
    for g in spheres {
        m.set_geom_margin(crate::mujoco::GeomId::from_index(g), offset, offset)?;
    }
    Ok(())
}

/// One environment.
#[derive(Debug)]
pub struct Env {
    id: &'static str,
    config: EnvConfig,
    /// ManiSkill's `_reconfig_counter`: resets left before a task with per-episode shapes
    /// draws them again (the frequency is `config.reconfiguration_freq`, resolved in `new`).
    reconfig_counter: u32,
    max_episode_steps: u32,
    sim: Sim,
    /// ManiSkill's actors (table first, then the task's), resolved to bodies.
    actors: Vec<state_dict::Actor>,
    numpy: NumpyRandomState,
    /// ManiSkill's main RNG: it draws the episode seed of an unseeded reset of a task whose
    /// shapes change every episode (`_batched_main_rng.randint(2**31)`).
    main_numpy: NumpyRandomState,
    torch_global: TorchGenerator,
    main_seed: Option<u64>,
    episode_seed: Option<u64>,
    elapsed_steps: u32,
    info: Info,
    noise: Vec<f64>,
    obs: Vec<f32>,
    obs_layout: Vec<(String, std::ops::Range<usize>)>,
    action_space: BoxSpace,
    observation_space: BoxSpace,
    scratch_state: Vec<f64>,
    vision: Option<render::Vision>,
    render_options: crate::mujoco::render::RenderOptions,
    /// ManiSkill's segmentation ids of the scene and of every geom.
    seg_ids: segmentation::SegmentationIds,
}

/// Creates an env (gymnasium's `make`). Like ManiSkill, the new env has already been reset
/// with seed 2022.
pub fn make(env_id: &str, config: EnvConfig) -> Result<Env, EnvError> {
    Env::new(env_id, config)
}

impl Env {
    fn new(env_id: &str, config: EnvConfig) -> Result<Env, EnvError> {
        let spec = env_spec(env_id)?;
        let rs = resolve_robot(spec, config.robot.as_deref())?;
        let mode = config
            .control_mode
            .clone()
            .unwrap_or_else(|| rs.control_modes[0].name().to_string());
        checks::check_qpos_noise(config.robot_init_qpos_noise)?;
        config.sim.validate()?;
        let mut task = (spec.make_task)(rs.id);
        let scene = build_scene(spec, rs, &mode, config.sim, task.as_ref())?;
        // A visual obs mode draws from the start: its render model is compiled now (any other
        // env compiles one at its first `render`).
        let render_model = match config.obs_mode.is_visual() {
            true => Some(Arc::new(scene.render_model().map_err(EnvError::Robot)?)),
            false => None,
        };
        let TableScene {
            model,
            ids: robot,
            controller,
            drives,
            ..
        } = scene;
        let mut model = model;
        task.resolve(&model)?;
        if config.sim.pinch_solver == PinchSolver::PhysxTgs {
            speculative_sphere_contacts(&mut model, task.grasp_object())?;
        }
        let data = Data::new(model.clone())?;
        let mut drives = drives;
        if config.sim.pinch_solver == PinchSolver::PhysxTgs {
            enable_pinch_replica(&model, &mut drives, rs, spec.id.id(), task.grasp_object())?;
        }
        let actors = state_dict::resolve_actors(&model, task.actor_names())?;
        let n = robot.joints.len();
        let keys = task.info_keys();
        let mut sim = Sim {
            spec: rs,
            data,
            robot,
            controller,
            drives,
            task,
            finger_forces: [[0.0; 3]; 2],
            qpos: vec![0.0; n],
            qvel: vec![0.0; n],
        };
        // The observation's layout: one pass of the writer that steps use (obs.rs).
        let values = vec![0.0; keys.len()];
        let mut obs_layout = Vec::new();
        let off = if config.obs_mode == ObsMode::None {
            0
        } else {
            sim.read_joints();
            let mut w = ObsWriter::layout(&mut obs_layout);
            sim.observe(&sim.ctx(), &values, config.obs_mode.is_state(), &mut w);
            w.len()
        };
        let (model, task, controller) = (sim.data.model(), &sim.task, &sim.controller);
        let (low, high) = controller.bounds();
        let action_space = BoxSpace {
            shape: vec![low.len()],
            low: low.to_vec(),
            high: high.to_vec(),
        };
        let observation_space = BoxSpace {
            shape: vec![off],
            low: vec![f32::NEG_INFINITY; off],
            high: vec![f32::INFINITY; off],
        };
        let max_episode_steps = config.max_episode_steps.unwrap_or(spec.max_episode_steps);
        let render_options = crate::mujoco::render::RenderOptions::default();
        let seg_ids =
            segmentation::SegmentationIds::new(model, &sim.robot.link_bodies, task.actor_names());
        let vision = match render_model {
            Some(render_model) => {
                let labels = segmentation::SegmentationIds::new(
                    &render_model,
                    &sim.robot.link_bodies,
                    task.actor_names(),
                )
                .geom_labels;
                Some(render::Vision::new(
                    &render_model,
                    task.cameras(),
                    rs.cameras,
                    config.obs_mode.textures(),
                    config.obs_mode.is_point_cloud(),
                    labels,
                    render_options,
                )?)
            }
            None => None,
        };
        // ManiSkill's default reconfiguration_freq for one env: 1 (and nothing to redraw
        // where the scene is fixed).
        let reconfiguration_freq = config.reconfiguration_freq.unwrap_or(1);
        let mut env = Env {
            id: spec.id.id(),
            reconfig_counter: 0,
            config: EnvConfig {
                robot: Some(rs.uid().to_string()),
                control_mode: Some(mode),
                reconfiguration_freq: Some(reconfiguration_freq),
                ..config
            },
            max_episode_steps,
            sim,
            actors,
            numpy: NumpyRandomState::new(CONSTRUCTION_SEED),
            main_numpy: NumpyRandomState::new(CONSTRUCTION_SEED),
            torch_global: TorchGenerator::default(),
            main_seed: None,
            episode_seed: None,
            elapsed_steps: 0,
            info: Info {
                elapsed_steps: 0,
                reconfigure: None,
                keys,
                values,
                warnings: Warnings::default(),
            },
            noise: vec![0.0; n],
            obs: vec![0.0; off],
            obs_layout,
            action_space,
            observation_space,
            scratch_state: Vec::new(),
            vision,
            render_options,
            seg_ids,
        };
        // ManiSkill's construction: a reconfiguring reset with seed 2022.
        env.reset_with(Some(CONSTRUCTION_SEED), true);
        Ok(env)
    }

    /// Env id.
    pub fn id(&self) -> &'static str {
        self.id
    }
    /// Contact forces (N, world frame) on the two grasp fingers from the task's grasp object
    /// in the last physics substep (what `is_grasping` reads).
    pub fn finger_forces(&self) -> &[[f64; 3]; 2] {
        &self.sim.finger_forces
    }
    /// The robot's joint drives (PD targets and PhysX's force law). Read access for
    /// inspecting the targets a control mode set; a clone stepped with a clone of
    /// [`Env::data`] replays the raw physics without the env (what `mjskill bench` times).
    pub fn drives(&self) -> &Drives {
        &self.sim.drives
    }
    /// Physics steps per env step.
    pub fn substeps(&self) -> usize {
        self.config.sim.substeps()
    }
    /// The effective configuration (robot and control mode filled in).
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }
    /// The robot.
    pub fn robot_id(&self) -> crate::robots::RobotId {
        self.sim.spec.id
    }
    /// Robot spec.
    pub(crate) fn robot_spec(&self) -> &'static RobotSpec {
        self.sim.spec
    }
    /// The control mode in use (the robot's default when the config names none).
    pub fn control_mode(&self) -> &str {
        self.sim.controller.mode()
    }
    /// The compiled model.
    pub fn model(&self) -> &Arc<Model> {
        self.sim.data.model()
    }
    /// The simulation data (read-only).
    pub fn data(&self) -> &Data {
        &self.sim.data
    }
    /// The `info` key of the task's grasp check (`is_grasped`, `is_peg_grasped`,
    /// `is_obj_grasped`).
    pub fn grasp_info_key(&self) -> &'static str {
        self.sim.task.grasp_flag()
    }
    /// Whether `info` key `key` is a boolean flag (0 or 1) rather than a measurement
    /// (PokeCube also reports two distances).
    pub fn info_is_flag(&self, key: &str) -> bool {
        self.sim.task.bool_info(key)
    }
    /// The TCP pose (ManiSkill's `agent.tcp_pose`) as position and raw quaternion (w, x, y, z),
    /// in full precision.
    pub fn tcp_pose(&self) -> ([f64; 3], [f64; 4]) {
        self.sim.robot.tcp_pose(&self.sim.data)
    }
    /// The robot's joint positions in ManiSkill's qpos order, in full precision (ManiSkill's
    /// `agent.robot.get_qpos()`; the observation holds them as `f32`).
    pub fn robot_qpos(&self) -> Vec<f64> {
        let mut q = vec![0.0; self.sim.robot.joints.len()];
        self.sim.robot.joints.qpos(&self.sim.data, &mut q);
        q
    }
    /// Indices (ManiSkill qpos/qvel order) of the gripper's joints: every joint below the link
    /// that carries the robot's gripper joints (the fingers, and the mimic carriage or the
    /// linkage they move). While a gripper pinches an object, PhysX reports a solver residual
    /// as their velocity, not their motion (docs/outcome-physics.md); `examples/ppo.py` hides
    /// these entries of `agent/qvel` from the policies it trains.
    pub fn gripper_joints(&self) -> Vec<usize> {
        let model = self.model();
        let (parent, dof_body) = (model.body_parentid(), model.dof_bodyid());
        let joints = &self.sim.robot.joints;
        let carriers: Vec<usize> = (0..joints.names.len())
            .filter(|&k| {
                self.sim
                    .spec
                    .gripper_joints
                    .contains(&joints.names[k].as_str())
            })
            .map(|k| parent[dof_body[joints.dof_adr[k]] as usize] as usize)
            .collect();
        let below = |mut b: usize| {
            while b != 0 {
                b = parent[b] as usize;
                if carriers.contains(&b) {
                    return true;
                }
            }
            false
        };
        (0..joints.names.len())
            .filter(|&k| below(dof_body[joints.dof_adr[k]] as usize))
            .collect()
    }
    /// Resolved robot ids.
    pub(crate) fn robot(&self) -> &RobotIds {
        &self.sim.robot
    }
    /// The task.
    pub(crate) fn task(&self) -> &dyn Task {
        self.sim.task.as_ref()
    }
    /// Steps until truncation.
    pub fn max_episode_steps(&self) -> u32 {
        self.max_episode_steps
    }
    /// Action space (normalised parts are [−1, 1]).
    pub fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }
    /// Observation space (flat state vector; empty for obs mode `none`).
    pub fn observation_space(&self) -> &BoxSpace {
        &self.observation_space
    }
    /// Names and ranges of the parts of the flat observation (the `state_dict` view).
    pub fn obs_layout(&self) -> &[(String, std::ops::Range<usize>)] {
        &self.obs_layout
    }
    /// The observation extras (`extra/…` keys without the prefix, with their lengths) the task
    /// writes with (`privileged`) or without its state-only keys, whatever the obs mode.
    pub fn extra_layout(&self, privileged: bool) -> Vec<(String, usize)> {
        let mut layout = Vec::new();
        let mut w = ObsWriter::layout(&mut layout);
        w.set_prefix("extra/");
        self.sim
            .task
            .observe_extra(&self.sim.ctx(), &self.info.values, privileged, &mut w);
        layout
            .into_iter()
            .map(|(k, r)| (k["extra/".len()..].to_string(), r.len()))
            .collect()
    }
    /// The current observation.
    pub fn obs(&self) -> &[f32] {
        if self.config.obs_mode == ObsMode::None {
            &[]
        } else {
            &self.obs
        }
    }
    /// A named part of the current observation (`state_dict` access), e.g. `"extra/tcp_pose"`.
    pub fn obs_part(&self, key: &str) -> Option<&[f32]> {
        self.obs_layout
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, r)| &self.obs[r.clone()])
    }
    /// The current info.
    pub fn info(&self) -> &Info {
        &self.info
    }
    /// Whether the task's shapes change every episode, drawn at each reset as upstream
    /// rebuilds its scene (PegInsertionSide-v1): a state dict, which holds poses but not
    /// shapes, then belongs to the episode of its seed.
    pub fn reconfigures(&self) -> bool {
        self.sim.task.reconfigures()
    }
    /// Main seed.
    pub fn main_seed(&self) -> Option<u64> {
        self.main_seed
    }
    /// Seed of the current episode (the last seeded reset).
    pub fn episode_seed(&self) -> Option<u64> {
        self.episode_seed
    }

    /// Like [`Env::reset`], but a seed above [`checks::MAX_SEED`] is an error
    /// ([`EnvError::BadSeed`]) and the env is left unchanged.
    pub fn try_reset(&mut self, seed: Option<u64>) -> Result<(&[f32], &Info), EnvError> {
        self.try_reset_with(seed, false)
    }

    /// [`Env::try_reset`] with ManiSkill's reset option `reconfigure` ([`Env::reset_with`]).
    pub fn try_reset_with(
        &mut self,
        seed: Option<u64>,
        reconfigure: bool,
    ) -> Result<(&[f32], &Info), EnvError> {
        if let Some(s) = seed {
            checks::check_seed(s)?;
        }
        Ok(self.reset_with(seed, reconfigure))
    }

    /// Resets (docs/env.md §3): with a seed, both RNG streams restart from it; without, the numpy
    /// stream continues and placement draws come from the env's global torch generator.
    /// Returns the observation and info (`reconfigure = false`).
    ///
    /// Seeds are 32-bit as in ManiSkill: a seed above [`checks::MAX_SEED`] is reduced mod 2³²
    /// by both RNG streams, so `reset(Some(s))` and `reset(Some(s + 2³²))` give the same
    /// episode (the seed itself is kept as given, e.g. in recordings). Use [`Env::try_reset`]
    /// to reject such seeds instead.
    pub fn reset(&mut self, seed: Option<u64>) -> (&[f32], &Info) {
        self.reset_with(seed, false)
    }

    /// [`Env::reset`] with ManiSkill's reset option `reconfigure`: a task whose shapes are
    /// drawn per episode (PegInsertionSide-v1) draws them from the episode seed when
    /// `reconfigure` is true or its [`EnvConfig::reconfiguration_freq`] count of resets has
    /// run out (every reset at ManiSkill's single-env default of 1), and keeps the last ones
    /// otherwise; `info.reconfigure` says which. Tasks with fixed scenes ignore it.
    pub fn reset_with(&mut self, seed: Option<u64>, reconfigure: bool) -> (&[f32], &Info) {
        if let Some(s) = seed {
            self.main_seed = Some(s);
            self.main_numpy = NumpyRandomState::new(s);
            self.episode_seed = Some(s);
            self.numpy = NumpyRandomState::new(s);
        }
        // ManiSkill's counter: set to the frequency when the scene is rebuilt, counted down
        // at every reset, a rebuild due when it reaches zero (never at frequency 0).
        let freq = self.config.reconfiguration_freq.unwrap_or(1);
        let reconfigure = self.sim.task.reconfigures()
            && (reconfigure || (self.reconfig_counter == 0 && freq != 0));
        if reconfigure {
            self.reconfig_counter = freq;
        }
        self.reconfig_counter = self.reconfig_counter.saturating_sub(1);
        if reconfigure {
            // ManiSkill's reconfiguring reset: the episode seed (drawn from the main RNG when
            // none is given) seeds the shapes' draws, then the episode's numpy stream afresh.
            let s = seed.unwrap_or_else(|| self.main_numpy.randint_2_31());
            self.sim.task.draw_geometry(&mut NumpyRandomState::new(s));
            self.apply_geometry();
            self.numpy = NumpyRandomState::new(s);
        }
        self.elapsed_steps = 0;
        // _clear_sim_state + agent.reset: zero every velocity and the solver warm start.
        self.sim.data.qvel_mut().fill(0.0);
        self.sim.data.qacc_warmstart_mut().fill(0.0);
        self.sim.data.set_time(0.0);
        // Table scene: robot placement and joint noise (numpy stream).
        self.sim.spec.init_qpos(
            &mut self.numpy,
            self.config.robot_init_qpos_noise,
            &mut self.noise,
            &mut self.sim.qpos,
        );
        if let Some(base) = self.sim.task.robot_repose() {
            let sigma = self.sim.task.repose_noise();
            self.sim.spec.repose_qpos(
                &mut self.numpy,
                sigma.unwrap_or(self.config.robot_init_qpos_noise),
                base,
                &mut self.noise,
                &mut self.sim.qpos,
            );
        }
        self.sim
            .robot
            .joints
            .set_qpos(&mut self.sim.data, &self.sim.qpos);
        // Task placement (torch stream: a fresh generator for seeded resets).
        match seed {
            Some(s) => {
                let mut torch = TorchGenerator::new(s);
                self.sim
                    .task
                    .initialize_episode(&mut self.sim.data, &mut torch);
            }
            None => self
                .sim
                .task
                .initialize_episode(&mut self.sim.data, &mut self.torch_global),
        }
        self.sim.robot.apply_gravity(&mut self.sim.data);
        self.sim.data.forward();
        self.sim
            .controller
            .reset(&self.sim.robot.joints, &self.sim.data, &mut self.sim.drives);
        self.sim.data.clear_warnings();
        // `info.warnings` belongs to the step that raised them, not to the new episode.
        self.info.warnings = Warnings::default();
        // Contacts are not refreshed by a reset (docs/env.md §3 step 8): the grasp check sees the
        // previous episode's last finger forces at the new poses.
        self.info.reconfigure = Some(reconfigure);
        self.update_outputs();
        (self.obs(), &self.info)
    }

    /// One control step (docs/env.md §4). Errors (wrong length, NaN/inf) leave the env unchanged.
    pub fn step(&mut self, action: &[f32]) -> Result<Step<'_>, EnvError> {
        self.check_action(action)?;
        self.sim.controller.set_action(
            action,
            &self.sim.robot.joints,
            &self.sim.data,
            &mut self.sim.drives,
        );
        Ok(self.advance())
    }

    /// An action's length and finiteness ([`Env::step`]'s errors).
    fn check_action(&self, action: &[f32]) -> Result<(), EnvError> {
        let expected = self.sim.controller.action_dim();
        if action.len() != expected {
            return Err(EnvError::ActionLength {
                got: action.len(),
                expected,
                mode: self.sim.controller.mode().to_string(),
            });
        }
        if let Some((index, &value)) = action.iter().enumerate().find(|(_, a)| !a.is_finite()) {
            return Err(EnvError::ActionNotFinite { index, value });
        }
        Ok(())
    }

    /// A control step without a new action (`action=None` upstream): the drives keep their
    /// targets while physics advances.
    pub fn step_no_action(&mut self) -> Step<'_> {
        self.advance()
    }

    fn advance(&mut self) -> Step<'_> {
        for _ in 0..self.config.sim.substeps() {
            self.sim.drives.step(&mut self.sim.data);
        }
        // mj_step leaves poses at the start of its last substep; observations, rewards and
        // success must see the poses of the final state.
        self.sim.data.update_kinematics();
        self.elapsed_steps = self.elapsed_steps.saturating_add(1);
        finger_forces(
            self.sim.data.model(),
            &self.sim.data,
            self.sim.robot.fingers,
            self.sim.task.grasp_object(),
            &mut self.sim.finger_forces,
        );
        // Where PhysX's step replica took the last physics step, the fingers' forces are its
        // contact impulses (MuJoCo's contacts did not move the robot or the object).
        if let Some(fingers) = self.sim.robot.fingers {
            let dt = self.sim.data.model().timestep();
            for (k, f) in fingers.iter().enumerate() {
                if let Some(force) = self.sim.drives.pinch_contact_force(f.index(), dt) {
                    self.sim.finger_forces[k] = force;
                }
            }
        }
        self.info.reconfigure = None;
        self.info.warnings = self.sim.data.warnings();
        self.sim.data.clear_warnings();
        let reward = self.update_outputs();
        Step {
            obs: if self.config.obs_mode == ObsMode::None {
                &[]
            } else {
                &self.obs
            },
            reward,
            terminated: self.info.success(),
            truncated: self.elapsed_steps >= self.max_episode_steps,
            info: &self.info,
        }
    }

    /// The step outputs of the current state, all from one [`TaskCtx`]: `info` (the task's
    /// `evaluate()`), the observation (unless the obs mode is `none`) and the reward, which it
    /// returns; then the sensor images are rendered.
    fn update_outputs(&mut self) -> f32 {
        if let Some(v) = self.vision.as_mut() {
            v.invalidate();
        }
        self.sim.read_joints();
        let sim = &self.sim;
        let ctx = sim.ctx();
        sim.task.evaluate(&ctx, &mut self.info.values);
        self.info.elapsed_steps = self.elapsed_steps;
        let with_obs = self.config.obs_mode != ObsMode::None;
        if with_obs {
            let privileged = self.config.obs_mode.is_state();
            let mut out = ObsWriter::values(&mut self.obs);
            sim.observe(&ctx, &self.info.values, privileged, &mut out);
        }
        let reward = match self.config.reward_mode {
            RewardMode::None => 0.0,
            RewardMode::Sparse => self.info.success() as u8 as f32,
            RewardMode::Dense => sim.task.dense_reward(&ctx, &self.info.values) as f32,
            RewardMode::NormalizedDense => {
                (sim.task.dense_reward(&ctx, &self.info.values) / sim.task.max_reward()) as f32
            }
        };
        if with_obs {
            self.render_sensors();
        }
        reward
    }

    /// Renders the sensor images of a visual obs mode (and marks the human frame stale).
    ///
    /// # Panics
    /// If EGL fails to make the env's GL context current after it was created successfully
    /// (the context is never left current on another thread, so this indicates a broken GL
    /// driver).
    fn render_sensors(&mut self) {
        if let Some(v) = self.vision.as_mut() {
            if let Err(e) = v.render_sensor(&self.sim.data) {
                panic!("rendering the sensor camera failed after the renderer was created: {e}");
            }
        }
    }

    /// Dense reward of the current state (independent of the reward mode).
    pub fn dense_reward(&self) -> f64 {
        self.sim
            .task
            .dense_reward(&self.sim.ctx(), &self.info.values)
    }

    /// Captures everything that determines the future.
    pub fn get_state(&self) -> EnvState {
        let mut physics = Vec::with_capacity(self.sim.data.state_len());
        self.sim.data.get_state(&mut physics);
        let mut controller =
            Vec::with_capacity(self.sim.controller.save_len() + self.sim.drives.save_len());
        self.sim.controller.save(&mut controller);
        self.sim.drives.save(&mut controller);
        EnvState {
            env_id: self.id.to_string(),
            robot: self.sim.spec.uid().to_string(),
            control_mode: self.sim.controller.mode().to_string(),
            physics,
            controller,
            elapsed_steps: self.elapsed_steps,
            finger_forces: self.sim.finger_forces,
            numpy: self.numpy.clone(),
            torch_global: self.torch_global.clone(),
            seeds: (self.main_seed, self.episode_seed),
            main_numpy: Some(self.main_numpy.clone()),
            geometry: self.sim.task.geometry(),
        }
    }

    /// Restores a state from [`Env::get_state`]; the following steps equal the original
    /// trajectory bitwise. A state that [`Env::check_state`] refuses is an error and the env
    /// is left unchanged.
    pub fn set_state(&mut self, s: &EnvState) -> Result<(), EnvError> {
        self.check_state(s)?;
        self.adopt_geometry(&s.geometry);
        self.sim
            .data
            .set_state(&s.physics)
            .map_err(|e| EnvError::BadState(e.to_string()))?;
        self.sim.robot.apply_gravity(&mut self.sim.data);
        let k = self.sim.controller.load(&s.controller);
        self.sim.drives.load(&s.controller[k..]);
        self.elapsed_steps = s.elapsed_steps;
        self.sim.finger_forces = s.finger_forces;
        self.numpy = s.numpy.clone();
        self.torch_global = s.torch_global.clone();
        (self.main_seed, self.episode_seed) = s.seeds;
        self.main_numpy = match &s.main_numpy {
            Some(m) => m.clone(),
            None => NumpyRandomState::new(self.main_seed.unwrap_or(CONSTRUCTION_SEED)),
        };
        self.update_outputs();
        Ok(())
    }

    /// Whether [`Env::set_state`] takes `s`, without applying it: a state of another env,
    /// robot or control mode, of other sizes, with a non-finite or out-of-range value
    /// (`checks::check_state_values`), or with an SO100 jaw release counter that is not a
    /// whole number of substeps from 0 to `u32::MAX` is an error naming the field and value.
    /// Every state [`Env::get_state`] returns passes; readers of recordings (`mjskill info`,
    /// `mjskill replay`) check recorded states with it.
    pub fn check_state(&self, s: &EnvState) -> Result<(), EnvError> {
        let mine = (self.id, self.sim.spec.uid(), self.sim.controller.mode());
        if (s.env_id.as_str(), s.robot.as_str(), s.control_mode.as_str()) != mine {
            return Err(EnvError::BadState(format!(
                "state is from {}/{}/{}, this env is {}/{}/{}",
                s.env_id, s.robot, s.control_mode, mine.0, mine.1, mine.2
            )));
        }
        // The controller part: the controller's targets, then the drives' (targets, and the
        // SO100 jaw's release counters; a state saved before the counters were part of it
        // restores them at zero).
        let ctl = self.sim.controller.save_len();
        let drives = &self.sim.drives;
        let sizes_ok = s.physics.len() == self.sim.data.state_len()
            && (s.controller.len() == ctl + drives.save_len()
                || s.controller.len() == ctl + drives.targets_len());
        if !sizes_ok {
            return Err(EnvError::BadState(format!(
                "state sizes {} / {} do not match this env's {} / {}",
                s.physics.len(),
                s.controller.len(),
                self.sim.data.state_len(),
                ctl + drives.save_len()
            )));
        }
        checks::check_state_values(self.sim.data.model(), s)?;
        if self.sim.task.reconfigures() || !s.geometry.is_empty() {
            self.sim
                .task
                .check_geometry(&s.geometry)
                .map_err(|e| EnvError::BadState(format!("geometry: {e}")))?;
        }
        if let Err((i, x, why)) = drives.check_saved(&s.controller[ctl..]) {
            return Err(EnvError::BadState(format!(
                "controller[{}] = {x} {why}",
                ctl + i
            )));
        }
        Ok(())
    }

    /// Takes the shapes of a state or of another env of the same task (none: a task whose
    /// shapes never change, or a state saved before they were part of it) and writes them
    /// into the model when they differ from the episode's.
    pub(super) fn adopt_geometry(&mut self, shapes: &[f64]) {
        if !shapes.is_empty() && shapes != self.sim.task.geometry() {
            self.sim.task.set_geometry(shapes);
            self.apply_geometry();
        }
    }

    /// Writes the task's current shapes into the physics model (in place: `mj_setConst`
    /// recomputes what depends on them), the props' weights into the forces that carry them,
    /// and rebuilds the renderer, if the env has one, for the new shapes.
    ///
    /// # Panics
    /// If the renderer cannot be rebuilt after it was first created successfully (out of
    /// memory, or a broken GL driver), as [`Env::step`]'s sensor rendering does.
    fn apply_geometry(&mut self) {
        let task = &self.sim.task;
        if let Err(e) = self.sim.data.edit_model(|m| task.apply_geometry(m)) {
            // The shapes are drawn within the task's ranges and its ids were resolved when
            // the env was built, so MuJoCo's checks cannot fail here.
            panic!("the task's shapes could not be written into its model: {e}");
        }
        self.sim.robot.prop_weights =
            crate::mjcf::prop_weights(self.sim.data.model(), &self.sim.robot.bodies);
        if self.vision.is_some() {
            match self.make_vision() {
                Ok(v) => self.vision = Some(v),
                Err(e) => panic!("the renderer could not be rebuilt for the new shapes: {e}"),
            }
        }
    }

    /// Raw physics state (for recording), written into `out`.
    pub fn physics_state(&mut self) -> &[f64] {
        let mut buf = std::mem::take(&mut self.scratch_state);
        self.sim.data.get_state(&mut buf);
        self.scratch_state = buf;
        &self.scratch_state
    }
}

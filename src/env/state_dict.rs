//! The env state in ManiSkill's terms: `get_state_dict` / `set_state_dict`, actor poses by
//! name and the per-part action split.
//!
//! ManiSkill's `env.get_state_dict()` (batch dim dropped) is
//! * `actors.<name>`: `[x, y, z, qw, qx, qy, qz, vx, vy, vz, wx, wy, wz]`, world frame, the
//!   linear velocity of the centre of mass; kinematic actors have zero velocities, static
//!   ones (the ground) are left out;
//! * `articulations.<robot>`: `[root pose (7), root linear vel (3), root angular vel (3),
//!   qpos (n), qvel (n)]` in ManiSkill's joint order;
//! * `controller[.<part>].target_qpos` / `target_pose`: the accumulated targets of the
//!   `*_target_*` control modes (nested under the part name when the mode has several parts).
//!
//! mjskill adds one entry ManiSkill's dict lacks: `drive`, the joints' PD drive targets
//! ([`DriveTargets`]). PhysX keeps its drive targets across `set_state_dict` (they are what the
//! last action set), so a ManiSkill state in which the gripper holds an object still squeezes
//! it; a state dict without `drive` cannot say that the fingers push, and importing it leaves
//! the drives at the imported positions. [`Env::set_state_dict_after_action`] imports such a
//! state with the targets the action that led to it sets.
//!
//! mjskill's robots are fixed at their table pose (the root is welded to the world), so a
//! state dict whose root pose differs from it is rejected rather than silently ignored.
use indexmap::IndexMap;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde_json::{json, Map, Value};

use super::checks::{MAX_STATE_VALUE, MAX_TARGET_VALUE};
use super::{Env, EnvError};
use crate::mujoco::{BodyId, JointId, JointType, MocapId, Model, Pose};

/// Largest root-pose difference [`Env::set_state_dict`] accepts (m, and rad for the
/// rotation): ManiSkill stores the pose in float32.
pub const ROOT_POSE_TOLERANCE: f64 = 1e-5;

/// `env.get_state_dict()` in ManiSkill's layout. Maps keep ManiSkill's order (actors in
/// scene order, then the articulation, then the controller state), which is also the order
/// of the flat `env.get_state()` vector ([`StateDict::flat`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StateDict {
    /// Actor name → pose (7) and velocities (6).
    pub actors: IndexMap<String, [f64; 13]>,
    /// Articulation name (the robot uid) → root pose (7), root velocities (6), qpos, qvel.
    pub articulations: IndexMap<String, Vec<f64>>,
    /// Controller state: `"<part>.target_qpos"` / `"<part>.target_pose"` for modes with
    /// several parts, `"target_qpos"` for single-part modes (so100).
    pub controller: IndexMap<String, Vec<f64>>,
    /// The drive targets (mjskill's addition; `None` in ManiSkill's own dicts): when given,
    /// [`Env::set_state_dict`] holds the drives on them instead of on the imported positions.
    pub drive: Option<DriveTargets>,
}

/// The PD drive targets of the robot's joints, in ManiSkill's joint order (what ManiSkill's
/// `robot.get_drive_targets()` / `get_drive_velocities()` return; undriven joints read 0 and
/// are ignored when set).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DriveTargets {
    /// Position target per joint (rad or m).
    pub qpos: Vec<f64>,
    /// Velocity target per joint (rad/s or m/s).
    pub qvel: Vec<f64>,
}

impl StateDict {
    /// The flat vector of ManiSkill's `env.get_state()` (leaves concatenated in order; the
    /// drive targets, which ManiSkill's vector lacks, are left out).
    pub fn flat(&self) -> Vec<f64> {
        let mut v = Vec::new();
        for a in self.actors.values() {
            v.extend_from_slice(a);
        }
        for a in self.articulations.values() {
            v.extend_from_slice(a);
        }
        for c in self.controller.values() {
            v.extend_from_slice(c);
        }
        v
    }

    /// ManiSkill's nested JSON form (`{"actors": {...}, "articulations": {...},
    /// "controller": {...}}`; no `controller` key when the mode keeps no state), plus
    /// `"drive": {"target_qpos": [...], "target_qvel": [...]}` when the drive targets are
    /// known (ManiSkill's `set_state_dict` ignores keys it does not know).
    pub fn to_json(&self) -> Value {
        let mut top = Map::new();
        top.insert("actors".into(), json!(self.actors));
        top.insert("articulations".into(), json!(self.articulations));
        if !self.controller.is_empty() {
            let mut c = Map::new();
            for (k, v) in &self.controller {
                match k.split_once('.') {
                    Some((part, key)) => {
                        let e = c
                            .entry(part.to_string())
                            .or_insert_with(|| Value::Object(Map::new()));
                        if let Value::Object(m) = e {
                            m.insert(key.to_string(), json!(v));
                        }
                    }
                    None => {
                        c.insert(k.clone(), json!(v));
                    }
                }
            }
            top.insert("controller".into(), Value::Object(c));
        }
        if let Some(d) = &self.drive {
            top.insert(
                "drive".into(),
                json!({"target_qpos": d.qpos, "target_qvel": d.qvel}),
            );
        }
        Value::Object(top)
    }

    /// Parses ManiSkill's nested JSON form (as [`StateDict::to_json`] writes it and as
    /// ManiSkill's `get_state_dict()` serialises). Errors name the offending key.
    pub fn from_json(v: &Value) -> Result<StateDict, StateDictError> {
        let obj = v.as_object().ok_or(StateDictError::NotJsonObject)?;
        for k in obj.keys() {
            if !matches!(
                k.as_str(),
                "actors" | "articulations" | "controller" | "drive"
            ) {
                return Err(StateDictError::UnknownKey(k.clone()));
            }
        }
        let floats = |key: &str, v: &Value| -> Result<Vec<f64>, StateDictError> {
            v.as_array()
                .ok_or_else(|| StateDictError::NotNumbers(key.to_string()))?
                .iter()
                .map(|x| {
                    x.as_f64().ok_or_else(|| StateDictError::NonNumber {
                        key: key.to_string(),
                        value: x.to_string(),
                    })
                })
                .collect()
        };
        let mut sd = StateDict::default();
        if let Some(a) = obj.get("actors") {
            let a = a.as_object().ok_or(StateDictError::NotObject("actors"))?;
            for (name, v) in a {
                let key = format!("actors.{name}");
                let f = floats(&key, v)?;
                let arr: [f64; 13] = f
                    .as_slice()
                    .try_into()
                    .map_err(|_| StateDictError::ActorLength { key, got: f.len() })?;
                sd.actors.insert(name.clone(), arr);
            }
        }
        if let Some(a) = obj.get("articulations") {
            let a = a
                .as_object()
                .ok_or(StateDictError::NotObject("articulations"))?;
            for (name, v) in a {
                sd.articulations
                    .insert(name.clone(), floats(&format!("articulations.{name}"), v)?);
            }
        }
        if let Some(c) = obj.get("controller") {
            let c = c
                .as_object()
                .ok_or(StateDictError::NotObject("controller"))?;
            for (k, v) in c {
                match v {
                    Value::Object(inner) => {
                        for (k2, v2) in inner {
                            let key = format!("{k}.{k2}");
                            let f = floats(&format!("controller.{key}"), v2)?;
                            sd.controller.insert(key, f);
                        }
                    }
                    _ => {
                        let f = floats(&format!("controller.{k}"), v)?;
                        sd.controller.insert(k.clone(), f);
                    }
                }
            }
        }
        if let Some(d) = obj.get("drive") {
            let d = d.as_object().ok_or(StateDictError::NotObject("drive"))?;
            if let Some(k) = d
                .keys()
                .find(|k| !matches!(k.as_str(), "target_qpos" | "target_qvel"))
            {
                return Err(StateDictError::UnknownKey(format!("drive.{k}")));
            }
            let qpos = match d.get("target_qpos") {
                Some(v) => floats("drive.target_qpos", v)?,
                None => return Err(StateDictError::Missing("drive.target_qpos")),
            };
            // Position-only drives: a missing velocity target is zero.
            let qvel = match d.get("target_qvel") {
                Some(v) => floats("drive.target_qvel", v)?,
                None => vec![0.0; qpos.len()],
            };
            sd.drive = Some(DriveTargets { qpos, qvel });
        }
        Ok(sd)
    }
}

/// Why a JSON value is not a state dict ([`StateDict::from_json`]); the message names the
/// offending key.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StateDictError {
    /// The value is not a JSON object.
    #[error("a state dict must be a JSON object")]
    NotJsonObject,
    /// One of the groups (`actors`, `articulations`, `controller`) is not a JSON object.
    #[error("{0} must be an object")]
    NotObject(&'static str),
    /// A top-level key other than `actors`, `articulations`, `controller` and `drive` (or a
    /// `drive` entry other than `target_qpos` and `target_qvel`).
    #[error(
        "unknown state dict key {0:?}; valid keys: actors, articulations, controller, drive \
         (drive: target_qpos, target_qvel)"
    )]
    UnknownKey(String),
    /// A required entry is missing.
    #[error("{0} is missing")]
    Missing(&'static str),
    /// An entry that is not an array.
    #[error("{0} must be an array of numbers")]
    NotNumbers(String),
    /// An array entry that is not a number.
    #[error("{key} holds a non-number {value}")]
    NonNumber {
        /// The entry's key.
        key: String,
        /// The offending JSON value.
        value: String,
    },
    /// An actor state without 13 values.
    #[error("{key} has {got} values, expected 13")]
    ActorLength {
        /// The actor's key.
        key: String,
        /// Values given.
        got: usize,
    },
}

/// How an actor of ManiSkill's scene is represented in the MuJoCo model.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum ActorBody {
    /// A dynamic actor: a body with a free joint.
    Free {
        /// Body id.
        body: BodyId,
        /// qpos address of the free joint.
        qadr: usize,
        /// dof address of the free joint.
        dadr: usize,
    },
    /// A kinematic actor: a mocap body.
    Mocap {
        /// Body id.
        body: BodyId,
        /// Mocap slot.
        mocap: MocapId,
    },
    /// A kinematic actor that never moves in mjskill (the table): its ManiSkill pose.
    Fixed([f64; 7]),
}

/// One ManiSkill actor, resolved.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Actor {
    /// ManiSkill's actor name.
    pub name: &'static str,
    /// Its MuJoCo representation.
    pub body: ActorBody,
}

/// The pose ManiSkill gives the table actor (`table-workspace`): its position and a 90° turn
/// about z. mjskill's table geom carries the same pose with its box centre half a height up.
fn table_pose() -> [f64; 7] {
    let p = crate::mjcf::props::TABLE_POS;
    let h = std::f64::consts::FRAC_1_SQRT_2;
    [p[0], p[1], p[2], h, 0.0, 0.0, h]
}

/// Resolves the actors of an env's scene: the table, then the task's actors in ManiSkill's
/// scene order. Errors name an actor the model lacks.
pub(crate) fn resolve_actors(
    model: &Model,
    task_actors: &[&'static str],
) -> Result<Vec<Actor>, EnvError> {
    let mut out = vec![Actor {
        name: crate::mjcf::TABLE,
        body: ActorBody::Fixed(table_pose()),
    }];
    for &name in task_actors {
        let body = model
            .require_body(name)
            .map_err(|_| EnvError::NoActorBody(name))?;
        let free = (0..model.njnt()).map(JointId::from_index).find(|&j| {
            model.jnt_bodyid()[j.index()] as usize == body.index()
                && model.joint_type(j.index()) == JointType::Free
        });
        let body = match (free, model.body_mocap(body)) {
            (Some(j), _) => ActorBody::Free {
                body,
                qadr: model.joint_qpos_adr(j),
                dadr: model.joint_dof_adr(j),
            },
            (None, Some(mocap)) => ActorBody::Mocap { body, mocap },
            _ => return Err(EnvError::ActorNotMovable(name)),
        };
        out.push(Actor { name, body });
    }
    Ok(out)
}

/// An orientation `(w, x, y, z)` from a state dict (renormalised: ManiSkill's are float32).
fn quat_of(q: &[f64]) -> UnitQuaternion<f64> {
    Pose {
        pos: [0.0; 3],
        quat: [q[0], q[1], q[2], q[3]],
    }
    .rotation_renormalized()
}

/// Angle between two (unnormalised) orientations, in radians.
fn rotation_distance(a: &[f64], b: &[f64]) -> f64 {
    quat_of(a).angle_to(&quat_of(b))
}

/// Checks that every value of `v` is finite and within ±`max` (the bounds of
/// [`Env::set_state`]: [`MAX_STATE_VALUE`] for poses and velocities, [`MAX_TARGET_VALUE`] for
/// controller targets), naming the first bad entry.
fn check_values(key: &str, v: &[f64], max: f64) -> Result<(), EnvError> {
    for (i, &x) in v.iter().enumerate() {
        if !x.is_finite() {
            return Err(EnvError::BadState(format!(
                "{key}[{i}] = {x} is not finite"
            )));
        }
        if x.abs() > max {
            return Err(EnvError::BadState(format!(
                "{key}[{i}] = {x} is out of range (|value| ≤ {max:e})"
            )));
        }
    }
    Ok(())
}

/// A named slice of the action vector (ManiSkill's `action_space` dict entry of one
/// controller part).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ActionPart {
    /// Part name (`arm`, `gripper`, `body`, `base`, `gripper_active`).
    pub name: &'static str,
    /// Position in the flat action vector.
    pub range: std::ops::Range<usize>,
    /// Lower bounds of the part's entries.
    pub low: Vec<f32>,
    /// Upper bounds of the part's entries.
    pub high: Vec<f32>,
}

impl Env {
    /// The pose `[x, y, z, qw, qx, qy, qz]` of a ManiSkill actor by name (`"cube"`,
    /// `"goal_site"`, `"table-workspace"`, ...); `None` for a name the scene lacks.
    pub fn actor_pose(&self, name: &str) -> Option<[f64; 7]> {
        let a = self.actors.iter().find(|a| a.name == name)?;
        Some(self.actor_state(a)[..7].try_into().expect("13 values"))
    }

    /// Names of the scene's actors in ManiSkill's order.
    pub fn actor_names(&self) -> Vec<&'static str> {
        self.actors.iter().map(|a| a.name).collect()
    }

    /// Names of the dynamic actors (the task's movable objects).
    pub fn dynamic_actor_names(&self) -> Vec<&'static str> {
        self.actors
            .iter()
            .filter(|a| matches!(a.body, ActorBody::Free { .. }))
            .map(|a| a.name)
            .collect()
    }

    fn actor_state(&self, a: &Actor) -> [f64; 13] {
        let d = &self.sim.data;
        let mut s = [0.0; 13];
        match a.body {
            ActorBody::Free { body, qadr, .. } => {
                s[..7].copy_from_slice(&d.qpos()[qadr..qadr + 7]);
                let v = d.body_velocity(body.index()); // [angular, linear at the COM], world
                s[7..10].copy_from_slice(&v[3..6]);
                s[10..13].copy_from_slice(&v[0..3]);
            }
            ActorBody::Mocap { mocap, .. } => {
                s[..Pose::LEN].copy_from_slice(&d.mocap_pose(mocap).to_array());
            }
            ActorBody::Fixed(p) => s[..7].copy_from_slice(&p),
        }
        s
    }

    /// The per-part split of the action vector (ManiSkill's `action_space` dict), in action
    /// order. Parts that take no action (the xArm6's passive linkage) are left out.
    pub fn action_parts(&self) -> Vec<ActionPart> {
        let (low, high) = self.sim.controller.bounds();
        self.sim
            .controller
            .part_ranges()
            .into_iter()
            .filter(|(_, r)| !r.is_empty())
            .map(|(name, r)| ActionPart {
                name,
                low: low[r.clone()].to_vec(),
                high: high[r.clone()].to_vec(),
                range: r,
            })
            .collect()
    }

    /// ManiSkill's `env.get_state_dict()` of the current state.
    pub fn get_state_dict(&self) -> StateDict {
        let mut sd = StateDict::default();
        for a in &self.actors {
            sd.actors.insert(a.name.to_string(), self.actor_state(a));
        }
        let root = self.sim.data.body_pose(self.sim.robot.root_body);
        let mut art = Vec::with_capacity(13 + 2 * self.sim.qpos.len());
        art.extend_from_slice(&root.to_array());
        art.extend_from_slice(&[0.0; 6]);
        let n = self.sim.qpos.len();
        let mut q = vec![0.0; n];
        self.sim.robot.joints.qpos(&self.sim.data, &mut q);
        art.extend_from_slice(&q);
        self.sim.robot.joints.qvel(&self.sim.data, &mut q);
        art.extend_from_slice(&q);
        sd.articulations
            .insert(self.sim.spec.uid().to_string(), art);
        for (key, v) in self.sim.controller.state_entries() {
            sd.controller.insert(key, v);
        }
        sd.drive = Some(self.drive_targets());
        sd
    }

    /// The drive targets the robot's joints are held on (ManiSkill's
    /// `robot.get_drive_targets()` / `get_drive_velocities()`; 0 for undriven joints).
    pub fn drive_targets(&self) -> DriveTargets {
        let n = self.sim.qpos.len();
        let (mut qpos, mut qvel) = (vec![0.0; n], vec![0.0; n]);
        for k in 0..n {
            if let Some((q, v)) = self.sim.drives.joint_target(k) {
                (qpos[k], qvel[k]) = (q, v);
            }
        }
        DriveTargets { qpos, qvel }
    }

    /// The drive targets `action` sets from the current state: what ManiSkill's controller
    /// hands PhysX in `env.step(action)` before the physics substeps (for delta modes they
    /// depend on the current joint positions). The env is left unchanged. Errors as
    /// [`Env::step`]'s for a bad action.
    pub fn action_drive_targets(&mut self, action: &[f32]) -> Result<DriveTargets, EnvError> {
        self.check_action(action)?;
        let mut saved = Vec::with_capacity(self.sim.controller.save_len());
        self.sim.controller.save(&mut saved);
        let mut drives = Vec::with_capacity(self.sim.drives.save_len());
        self.sim.drives.save(&mut drives);
        self.sim.controller.set_action(
            action,
            &self.sim.robot.joints,
            &self.sim.data,
            &mut self.sim.drives,
        );
        let targets = self.drive_targets();
        self.sim.controller.load(&saved);
        self.sim.drives.load(&drives);
        Ok(targets)
    }

    /// Imports `after`, a state ManiSkill reached by `action` from the env's current state
    /// (typically the previous row of the same trajectory, imported before), with the drive
    /// targets that action sets ([`Env::action_drive_targets`]) unless `after` carries its
    /// own. ManiSkill's recorded states lack the drive targets that PhysX keeps across
    /// steps; with them the imported state evaluates as in ManiSkill: fingers that hold an
    /// object squeeze it (`is_grasped`, the dense reward), a velocity-driven base keeps its
    /// commanded velocity. Errors as [`Env::set_state_dict`]'s, and for a bad action.
    pub fn set_state_dict_after_action(
        &mut self,
        action: &[f32],
        after: &StateDict,
    ) -> Result<(), EnvError> {
        if after.drive.is_some() {
            return self.set_state_dict(after);
        }
        let drive = self.action_drive_targets(action)?;
        let mut sd = after.clone();
        sd.drive = Some(drive);
        self.set_state_dict(&sd)
    }

    /// Sets the state from ManiSkill's `get_state_dict()` layout (as
    /// [`Env::get_state_dict`] returns it). Every actor and the robot must be present; the
    /// controller entries of `*_target_*` modes are optional (missing ones keep their
    /// values). Afterwards the drives hold the dict's `drive` targets if it has them, else
    /// the new positions (or the restored controller targets); contacts are recomputed
    /// with those drive forces, and `obs`, `info` and every reward mode describe the new
    /// state; `elapsed_steps` and the RNG streams are unchanged. Values have the bounds of
    /// [`Env::set_state`]: poses and velocities within ±1e10 (`MAX_STATE_VALUE`), controller and
    /// drive targets within ±`f32::MAX` (`MAX_TARGET_VALUE`, the largest f32, as targets are observed
    /// as f32). Errors (missing or unknown names, wrong lengths, non-finite or out-of-range
    /// values, a root pose other than the robot's fixed table pose) leave the env unchanged.
    ///
    /// ManiSkill's own dicts have no `drive`: a state in which the gripper holds an object
    /// then loses the squeeze (`is_grasped` false). [`Env::set_state_dict_after_action`]
    /// supplies the targets of the action that led to the state.
    pub fn set_state_dict(&mut self, sd: &StateDict) -> Result<(), EnvError> {
        // Validate everything before touching the simulation.
        self.check_state_dict_actors(sd)?;
        let art = self.check_state_dict_robot(sd)?;
        let n = self.sim.qpos.len();
        // Write the state.
        self.write_state_dict_actors(sd);
        self.sim
            .robot
            .joints
            .set_qpos(&mut self.sim.data, &art[13..13 + n]);
        let qv = self.sim.data.qvel_mut();
        for (&a, &v) in self.sim.robot.joints.dof_adr.iter().zip(&art[13 + n..]) {
            qv[a] = v;
        }
        self.sim.controller.set_targets_from_state(
            &self.sim.robot.joints,
            &self.sim.data,
            &mut self.sim.drives,
            &sd.controller,
        );
        if let Some(d) = &sd.drive {
            for k in 0..n {
                self.sim.drives.set_joint_target(k, d.qpos[k], d.qvel[k]);
            }
        }
        self.sim.data.qacc_warmstart_mut().fill(0.0);
        self.refresh_after_state_change();
        Ok(())
    }

    /// The errors of [`Env::set_state_dict`] about the dict's actors.
    fn check_state_dict_actors(&self, sd: &StateDict) -> Result<(), EnvError> {
        for name in sd.actors.keys() {
            if !self.actors.iter().any(|a| a.name == name) {
                return Err(EnvError::BadState(format!(
                    "unknown actor {name:?}; this scene's actors: {}",
                    self.actor_names().join(", ")
                )));
            }
        }
        for a in &self.actors {
            let s = sd.actors.get(a.name).ok_or_else(|| {
                EnvError::BadState(format!("state dict lacks actor {:?}", a.name))
            })?;
            check_values(&format!("actors.{}", a.name), s, MAX_STATE_VALUE)?;
            if let ActorBody::Fixed(p) = a.body {
                let dp = Vector3::from_column_slice(&s[..3]) - Vector3::from_column_slice(&p[..3]);
                if dp.norm() > ROOT_POSE_TOLERANCE
                    || rotation_distance(&s[3..7], &p[3..7]) > ROOT_POSE_TOLERANCE
                {
                    return Err(EnvError::BadState(format!(
                        "actor {:?} is fixed at {p:?} in mjskill; the state dict puts it at {:?}",
                        a.name,
                        &s[..7]
                    )));
                }
            }
        }
        Ok(())
    }

    /// The errors of [`Env::set_state_dict`] about the robot (articulation, controller and
    /// drive entries); returns the articulation's values.
    fn check_state_dict_robot<'a>(&self, sd: &'a StateDict) -> Result<&'a [f64], EnvError> {
        let uid = self.sim.spec.uid();
        if let Some(other) = sd.articulations.keys().find(|k| k.as_str() != uid) {
            return Err(EnvError::BadState(format!(
                "unknown articulation {other:?}; this env's robot is {uid:?}"
            )));
        }
        let art = sd
            .articulations
            .get(uid)
            .ok_or_else(|| EnvError::BadState(format!("state dict lacks articulation {uid:?}")))?;
        let n = self.sim.qpos.len();
        if art.len() != 13 + 2 * n {
            return Err(EnvError::BadState(format!(
                "articulations.{uid} has {} values, expected {} (root pose 7, root velocity 6, \
                 qpos {n}, qvel {n})",
                art.len(),
                13 + 2 * n
            )));
        }
        check_values(&format!("articulations.{uid}"), art, MAX_STATE_VALUE)?;
        let root = self.sim.data.body_pose(self.sim.robot.root_body);
        let (rp, rq) = (root.pos, root.quat);
        let dp = Vector3::from_column_slice(&art[..3]) - Vector3::from(rp);
        if dp.norm() > ROOT_POSE_TOLERANCE
            || rotation_distance(&art[3..7], &rq) > ROOT_POSE_TOLERANCE
            || art[7..13].iter().any(|v| *v != 0.0)
        {
            return Err(EnvError::BadState(format!(
                "the robot's root is fixed at {:?} with zero velocity in mjskill; the state \
                 dict gives pose {:?} and velocity {:?}",
                [rp[0], rp[1], rp[2], rq[0], rq[1], rq[2], rq[3]],
                &art[..7],
                &art[7..13]
            )));
        }
        let expected: Vec<(String, usize)> = self
            .sim
            .controller
            .state_entries()
            .into_iter()
            .map(|(k, v)| (k, v.len()))
            .collect();
        for (k, v) in &sd.controller {
            match expected.iter().find(|(e, _)| e == k) {
                None => {
                    return Err(EnvError::BadState(format!(
                        "unknown controller state {k:?} for control mode {}; valid: {}",
                        self.sim.controller.mode(),
                        if expected.is_empty() {
                            "none".to_string()
                        } else {
                            expected
                                .iter()
                                .map(|e| e.0.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        }
                    )))
                }
                Some((_, len)) if *len != v.len() => {
                    return Err(EnvError::BadState(format!(
                        "controller.{k} has {} values, expected {len}",
                        v.len()
                    )))
                }
                _ => check_values(&format!("controller.{k}"), v, MAX_TARGET_VALUE)?,
            }
        }
        if let Some(d) = &sd.drive {
            for (key, v) in [
                ("drive.target_qpos", &d.qpos),
                ("drive.target_qvel", &d.qvel),
            ] {
                if v.len() != n {
                    return Err(EnvError::BadState(format!(
                        "{key} has {} values, expected {n} (one per joint of {uid})",
                        v.len()
                    )));
                }
                check_values(key, v, MAX_TARGET_VALUE)?;
            }
        }
        Ok(art.as_slice())
    }

    /// Writes the actors' poses and velocities of a checked state dict.
    fn write_state_dict_actors(&mut self, sd: &StateDict) {
        for a in &self.actors {
            let s = &sd.actors[a.name];
            match a.body {
                ActorBody::Free { qadr, dadr, body } => {
                    self.sim.data.qpos_mut()[qadr..qadr + 7].copy_from_slice(&s[..7]);
                    // qvel of a free joint: linear velocity of the body origin (world) and
                    // angular velocity in the body frame; ManiSkill gives the centre of mass's
                    // linear velocity and the world angular velocity.
                    let r = quat_of(&s[3..7]).to_rotation_matrix();
                    let w = Vector3::from_column_slice(&s[10..13]);
                    let ipos = self.sim.data.model().body_com_offset(body);
                    let com_offset: Vector3<f64> = r * Vector3::from(ipos);
                    let v_origin = Vector3::from_column_slice(&s[7..10]) - w.cross(&com_offset);
                    let w_local: Vector3<f64> = Matrix3::from(r).transpose() * w;
                    let qv = &mut self.sim.data.qvel_mut()[dadr..dadr + 6];
                    qv[..3].copy_from_slice(v_origin.as_slice());
                    qv[3..].copy_from_slice(w_local.as_slice());
                }
                ActorBody::Mocap { mocap, .. } => {
                    let pose = Pose::from_slice(s).expect("checked: 13 values per actor");
                    self.sim.data.set_mocap_pose(mocap, &pose);
                }
                ActorBody::Fixed(_) => {}
            }
        }
    }

    /// Recomputes everything derived from the simulation state (forward dynamics, contacts,
    /// finger forces, info and observation) after the state was written from outside.
    fn refresh_after_state_change(&mut self) {
        // The drive forces of the new state take part in the contact forces.
        self.sim.data.forward();
        let dt = self.sim.data.model().timestep();
        self.sim.drives.apply(&mut self.sim.data, dt);
        self.sim.data.forward();
        crate::tasks::finger_forces(
            self.sim.data.model(),
            &self.sim.data,
            self.sim.robot.fingers,
            self.sim.task.grasp_object(),
            &mut self.sim.finger_forces,
        );
        self.update_outputs();
    }

    /// Sets `elapsed_steps` (ManiSkill's state dict does not carry it; `info` and
    /// `truncated` follow it).
    pub fn set_elapsed_steps(&mut self, steps: u32) {
        self.elapsed_steps = steps;
        self.info.elapsed_steps = steps;
    }
}

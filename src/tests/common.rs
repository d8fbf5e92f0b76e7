//! Helpers shared by the crate's internal tests: an independent URDF forward kinematics
//! (roxmltree, not urdf-rs and not mjskill's loader), a table scene with PD targets, env
//! construction, a determinism check, and the task tests' observation and state helpers.
use std::collections::HashMap;
use std::sync::Arc;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};

use crate::controllers::Drives;
use crate::env::{make, EnvConfig};
use crate::mujoco::{Data, Model};
use crate::robots::{self, RobotIds, RobotSpec};

/// (name, type, parent, child, origin, axis) of one URDF joint.
type JointRow = (String, String, String, String, Isometry3<f64>, Vector3<f64>);

/// numpy's `RandomState(0).normal(0, 1, 12)` (ManiSkill's table-scene qpos noise source).
pub const NUMPY_SEED0_NORMALS: [f64; 12] = [
    1.764052345967664,
    0.4001572083672233,
    0.9787379841057392,
    2.240893199201458,
    1.8675579901499675,
    -0.977277879876411,
    0.9500884175255894,
    -0.1513572082976979,
    -0.10321885179355784,
    0.41059850193837233,
    0.144043571160878,
    1.454273506962975,
];

/// Forward kinematics straight from the URDF text (roxmltree; not urdf-rs, not mjskill's
/// loader): composes origin · motion along the tree.
pub struct IndependentFk {
    joints: Vec<JointRow>,
}

fn parse_floats(s: Option<&str>, default: [f64; 3]) -> [f64; 3] {
    match s {
        None => default,
        Some(t) => {
            let v: Vec<f64> = t.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        }
    }
}

impl IndependentFk {
    pub fn new(urdf: &str) -> Self {
        let doc = roxmltree::Document::parse(urdf).unwrap();
        let mut joints = Vec::new();
        for j in doc
            .root_element()
            .children()
            .filter(|n| n.has_tag_name("joint"))
        {
            let child = |tag: &str| j.children().find(|n| n.has_tag_name(tag));
            let origin = child("origin");
            let xyz = parse_floats(origin.and_then(|o| o.attribute("xyz")), [0.0; 3]);
            let rpy = parse_floats(origin.and_then(|o| o.attribute("rpy")), [0.0; 3]);
            // rpy: fixed-axis roll, pitch, yaw ⇒ R = Rz(y)·Ry(p)·Rx(r)
            let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rpy[2])
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), rpy[1])
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), rpy[0]);
            let axis = Vector3::from(parse_floats(
                child("axis").and_then(|a| a.attribute("xyz")),
                [1.0, 0.0, 0.0],
            ));
            let link = |tag: &str| child(tag).unwrap().attribute("link").unwrap().to_string();
            joints.push((
                j.attribute("name").unwrap().to_string(),
                j.attribute("type").unwrap().to_string(),
                link("parent"),
                link("child"),
                Isometry3::from_parts(Translation3::new(xyz[0], xyz[1], xyz[2]), rot),
                axis.normalize(),
            ));
        }
        IndependentFk { joints }
    }

    /// World pose of every link for joint values by name.
    pub fn links(
        &self,
        base: &Isometry3<f64>,
        root: &str,
        q: &HashMap<String, f64>,
    ) -> HashMap<String, Isometry3<f64>> {
        let mut out = HashMap::from([(root.to_string(), *base)]);
        loop {
            let mut added = false;
            for (name, ty, parent, child, origin, axis) in &self.joints {
                if out.contains_key(child) || !out.contains_key(parent) {
                    continue;
                }
                let v = q.get(name).copied().unwrap_or(0.0);
                let motion = match ty.as_str() {
                    "revolute" | "continuous" => Isometry3::rotation(axis * v),
                    "prismatic" => Isometry3::translation(axis.x * v, axis.y * v, axis.z * v),
                    _ => Isometry3::identity(),
                };
                let p = out[parent] * origin * motion;
                out.insert(child.clone(), p);
                added = true;
            }
            if !added {
                return out;
            }
        }
    }
}

/// Uniform joint values within the limits (ManiSkill order).
pub fn uniform_q(rng: &mut rand::rngs::StdRng, ids: &RobotIds) -> Vec<f64> {
    ids.joints
        .limits
        .iter()
        .map(|&(lo, hi)| rng.random_range(lo..=hi))
        .collect()
}

/// Checks MuJoCo's link poses of `uid` at its table pose against [`IndependentFk`] over
/// random configurations within the joint limits; calls `extra` with the data and the
/// independent link poses of each sample.
pub fn check_fk(
    uid: &str,
    samples: usize,
    extra: impl FnMut(&Data, &RobotIds, &HashMap<String, Isometry3<f64>>),
) {
    check_fk_with(uid, samples, uniform_q, extra)
}

/// [`check_fk`] with configurations drawn by `sample` (ManiSkill order).
pub fn check_fk_with(
    uid: &str,
    samples: usize,
    mut sample: impl FnMut(&mut rand::rngs::StdRng, &RobotIds) -> Vec<f64>,
    mut extra: impl FnMut(&Data, &RobotIds, &HashMap<String, Isometry3<f64>>),
) {
    let spec = robots::spec(uid).unwrap();
    let robots::TableScene { model, ids, .. } = robots::table_scene_with(spec, |_| {}).unwrap();
    let desc = spec.description().unwrap();
    let fk = IndependentFk::new(crate::models::text(spec.urdf).unwrap());
    let mut d = Data::new(model.clone()).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let root = &desc.links[desc.root].name;
    for _ in 0..samples {
        let qv = sample(&mut rng, &ids);
        let q: HashMap<String, f64> = ids.joints.names.iter().cloned().zip(qv.clone()).collect();
        ids.joints.set_qpos(&mut d, &qv);
        d.forward();
        let want = fk.links(&spec.table_base(), root, &q);
        assert_eq!(
            want.len(),
            desc.links.len(),
            "independent FK reached every link"
        );
        for (name, b) in &ids.link_bodies {
            let got = RobotIds::body_pose(&d, *b);
            let w = want[name];
            let dp = (got.translation.vector - w.translation.vector).norm();
            let dr = got.rotation.angle_to(&w.rotation);
            assert!(dp < 1e-6, "{uid} link {name}: position error {dp}");
            assert!(dr < 1e-6, "{uid} link {name}: rotation error {dr}");
        }
        extra(&d, &ids, &want);
    }
}

/// The table scene of `spec` at its (noise-free) table qpos with the drive targets there and
/// gravity applied (none on the robot): model, ids, data and drives.
pub fn table_scene(spec: &RobotSpec) -> (Arc<Model>, RobotIds, Data, Drives) {
    table_scene_with(spec, |_| {})
}

/// [`table_scene`] with `extra` adding objects to the scene.
pub fn table_scene_with(
    spec: &RobotSpec,
    extra: impl FnOnce(&mut crate::mjcf::Scene),
) -> (Arc<Model>, RobotIds, Data, Drives) {
    table_scene_at(spec, crate::mjcf::TIMESTEP, extra)
}

/// [`table_scene_with`] at physics timestep `timestep`.
pub fn table_scene_at(
    spec: &RobotSpec,
    timestep: f64,
    extra: impl FnOnce(&mut crate::mjcf::Scene),
) -> (Arc<Model>, RobotIds, Data, Drives) {
    let robots::TableScene {
        model,
        ids,
        mut drives,
        ..
    } = robots::table_scene_at(spec, timestep, extra).unwrap();
    let mut d = Data::new(model.clone()).unwrap();
    ids.joints.set_qpos(&mut d, spec.table_qpos);
    ids.apply_gravity(&mut d);
    for (k, &q) in spec.table_qpos.iter().enumerate() {
        drives.set_joint_target(k, q, 0.0);
    }
    d.forward();
    (model, ids, d, drives)
}

/// Holds the table pose for 5 s (sag < 1e-3 rad on every driven joint), then tracks a step
/// of `delta` on the driven joints within `tol` after 1.5 s without touching anything.
pub fn holds_and_tracks(spec: &RobotSpec, delta: &[f64], tol: f64) {
    let (model, ids, mut d, mut dr) = table_scene(spec);
    assert!(model.gravity()[2] < -9.0);
    let n = ids.joints.qpos_adr.len();
    run(&mut d, &mut dr, (5.0 / model.timestep()).round() as usize);
    let mut q = vec![0.0; n];
    ids.joints.qpos(&d, &mut q);
    for (k, (qk, rest)) in q.iter().zip(spec.table_qpos).enumerate() {
        let sag = (qk - rest).abs();
        assert!(
            sag < 1e-3,
            "{} joint {k} drifted {sag} over 5 s",
            spec.uid()
        );
    }
    assert!(!d.warnings().diverged(), "{:?}", d.warnings());
    let target: Vec<f64> = spec
        .table_qpos
        .iter()
        .zip(delta)
        .map(|(q, dq)| q + dq)
        .collect();
    for (k, &t) in target.iter().enumerate() {
        dr.set_joint_target(k, t, 0.0);
    }
    run(&mut d, &mut dr, (1.5 / model.timestep()) as usize);
    ids.joints.qpos(&d, &mut q);
    for k in 0..n {
        if ids.joints.actuator[k].is_some() {
            let e = (q[k] - target[k]).abs();
            assert!(
                e < tol,
                "{} joint {k}: tracking error {e} after 1.5 s",
                spec.uid()
            );
        }
    }
    assert!(!d.warnings().diverged(), "{:?}", d.warnings());
}

/// Steps `n` physics substeps with the drives.
pub fn run(d: &mut Data, drives: &mut Drives, n: usize) {
    for _ in 0..n {
        drives.step(d);
    }
}

/// `id` with its default robot in control mode `mode`.
pub fn env(id: &str, mode: &str) -> crate::env::Env {
    make(
        id,
        EnvConfig {
            control_mode: Some(mode.into()),
            ..Default::default()
        },
    )
    .unwrap()
}

/// `id` with `robot` (default control mode), or the error.
pub fn env_with_robot(id: &str, robot: &str) -> Result<crate::env::Env, crate::env::EnvError> {
    make(
        id,
        EnvConfig {
            robot: Some(robot.into()),
            ..Default::default()
        },
    )
}

/// Two 30-step runs of the scripted solver on `id` in `mode` from seed 5 give bitwise
/// identical observations and rewards.
pub fn assert_solver_rollout_is_deterministic(id: &str, mode: &str) {
    let run = || {
        let mut e = env(id, mode);
        let mut policy = crate::solvers::make_policy("solver", &e, 0).unwrap();
        let mut a = vec![0.0f32; e.action_space().shape[0]];
        e.reset(Some(5));
        policy.reset(&e);
        let mut trace: Vec<u32> = Vec::new();
        for _ in 0..30 {
            policy.act(&e, &mut a);
            let s = e.step(&a).unwrap();
            trace.extend(s.obs.iter().map(|x| x.to_bits()));
            trace.push(s.reward.to_bits());
        }
        trace
    };
    assert_eq!(run(), run());
}

/// The scripted solver on `id` in `mode`: on the first 3 seeds of 0..20 whose goal is at
/// least `min_goal_z` high, 50 steps grasp the cube at some step and end grasped and
/// successful with the cube above `min_cube_z`; `check(env, seed)` then tests the end state.
pub fn solver_grasps_and_lifts(
    id: &str,
    mode: &str,
    min_goal_z: f32,
    min_cube_z: f32,
    mut check: impl FnMut(&crate::env::Env, u64),
) {
    let mut e = env(id, mode);
    let mut policy = crate::solvers::make_policy("solver", &e, 0).unwrap();
    let mut a = vec![0.0f32; e.action_space().shape[0]];
    let mut tested = 0;
    for seed in 0..20u64 {
        e.reset(Some(seed));
        if e.obs_part("extra/goal_pos").unwrap()[2] < min_goal_z {
            continue; // want a goal well above the table
        }
        policy.reset(&e);
        let mut grasped_at = None;
        for t in 0..50 {
            policy.act(&e, &mut a);
            let s = e.step(&a).unwrap();
            if s.info.flag("is_grasped") && grasped_at.is_none() {
                grasped_at = Some(t);
            }
        }
        assert!(grasped_at.is_some(), "seed {seed}: never grasped");
        let info = e.info();
        assert!(
            info.flag("is_grasped") && info.success(),
            "seed {seed}: {info:?}"
        );
        let obj = e.obs_part("extra/obj_pose").unwrap();
        assert!(
            obj[2] > min_cube_z,
            "seed {seed}: the cube was lifted, z = {}",
            obj[2]
        );
        check(&e, seed);
        tested += 1;
        if tested == 3 {
            break;
        }
    }
    assert_eq!(tested, 3);
}

// ---- task tests: observations and constructed states --------------------------------

/// Asserts that `got` equals `want` element by element within `tol` (same length).
pub fn close(got: &[f32], want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (*g as f64 - w).abs() < tol,
            "{what}[{k}]: got {g}, want {w}"
        );
    }
}

/// A named observation slice (`"extra/tcp_pose"`) as f64.
pub fn part(e: &crate::env::Env, key: &str) -> Vec<f64> {
    e.obs_part(key).unwrap().iter().map(|&x| x as f64).collect()
}

/// Euclidean norm.
pub fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Writes the pose of the free body whose free joint is `joint` (zero velocity) through the
/// env state: `physics` = [time, qpos (nq), qvel (nv), ...].
pub fn put_free_body(e: &mut crate::env::Env, joint: &str, pos: [f64; 3], quat: [f64; 4]) {
    let model = e.model().clone();
    let j = model
        .require_id(crate::mujoco::ObjType::Joint, joint)
        .unwrap();
    let adr = model.jnt_qposadr()[j] as usize;
    let vadr = model.jnt_dofadr()[j] as usize;
    let nq = model.nq();
    let mut st = e.get_state();
    st.physics[1 + adr..1 + adr + 3].copy_from_slice(&pos);
    st.physics[1 + adr + 3..1 + adr + 7].copy_from_slice(&quat);
    st.physics[1 + nq + vadr..1 + nq + vadr + 6].fill(0.0);
    e.set_state(&st).unwrap();
}

/// Sets the robot's joint velocities (ManiSkill order) through the env state.
pub fn set_robot_qvel(e: &mut crate::env::Env, qvel: &[f64]) {
    let nq = e.model().nq();
    let dofs = e.robot().joints.dof_adr.clone();
    let mut st = e.get_state();
    for (&a, &v) in dofs.iter().zip(qvel) {
        st.physics[1 + nq + a] = v;
    }
    e.set_state(&st).unwrap();
}

//! Agreement with ManiSkill 3 itself: the reference trajectories recorded from ManiSkill
//! (PhysX CPU) in `tests/data/maniskill/` (format: `docs/reference-trajectories.md`), one
//! file per registered (env, robot) pair.
//!
//! * Seeded initial states equal ManiSkill's.
//! * Observation, rewards and info computed on ManiSkill's own recorded states (imported
//!   through `set_state_dict`) equal ManiSkill's; the grasp flag wherever the finger contacts
//!   agree.
//! * Open-loop replay of ManiSkill's actions tracks ManiSkill's joints, TCP and objects within
//!   limits set from measurement (`MEASURED`), and motion-planning episodes succeed where
//!   ManiSkill's did.
use std::path::PathBuf;

use mjskill::maniskill::fidelity::{env_for, replay_file, FidelityOptions, StepError};
use mjskill::maniskill::merged_actor_name;
use mjskill::maniskill::reference::{RefFile, Snapshot};
use mjskill::{Env, SimConfig};

mod common;

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/maniskill")
}

/// Every reference file, one per registered (env, robot) pair.
fn files() -> Vec<RefFile> {
    let mut out = Vec::new();
    for e in mjskill::registry() {
        for (robot, _) in &e.robots {
            let p = data_dir().join(format!("{}__{robot}.json.gz", e.id));
            out.push(RefFile::open(&p).unwrap_or_else(|err| panic!("{err}")));
        }
    }
    assert_eq!(out.len(), 22, "one file per registered pair");
    out
}

fn max_abs(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// ManiSkill's quaternions are neither normalised nor sign-canonical: compare rotations.
fn quat_angle(a: &[f64], b: &[f64]) -> f64 {
    let q = |v: &[f64]| {
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(v[0], v[1], v[2], v[3]))
    };
    q(a).angle_to(&q(b))
}

fn robot_qpos(env: &Env) -> Vec<f64> {
    env.robot_qpos()
}

/// Envs whose dense reward checks the grasp although `info` does not report it
/// (LiftPegUpright's reaching term is full while the peg is grasped).
const UNREPORTED_GRASP: [&str; 2] = ["LiftPegUpright-v1", "PegInsertionSide-v1"];

/// Envs whose dense reward checks the grasp with a tighter angle than the robot's own check
/// (PegInsertionSide-v1: 20°). MuJoCo's contact normals between the Panda's pads and a held
/// peg lean 15–25° off the fingers' axis where PhysX's lie within 6° (docs/agreement.md), so
/// their rewards are compared where neither sim's fingers touch the object.
const ANGLE_GRASP_REWARD: [&str; 1] = ["PegInsertionSide-v1"];

/// Compares everything that is a function of the state: poses, TCP, obs (except the grasp
/// flag, `skip_obs`), rewards and the info flags. `contacts_agree`: both sims see the fingers
/// touching the grasp object or both see them free; where they do not, the reward of an
/// [`UNREPORTED_GRASP`] env is not compared (a plain import loses the squeeze; the held-state
/// test compares those rewards with the drive targets restored). `fingers_free`: neither sim
/// sees them touching it; only then is the reward of an [`ANGLE_GRASP_REWARD`] env compared.
fn check_state_quantities(
    env: &Env,
    s: &Snapshot,
    grasp_key: &str,
    grasp_obs: Option<usize>,
    contacts_agree: bool,
    fingers_free: bool,
    ctx: &str,
) -> bool {
    assert!(
        max_abs(&robot_qpos(env), &s.robot_qpos) < 1e-6,
        "{ctx}: qpos"
    );
    for (name, pose) in &s.actors {
        if name == "ground" {
            continue;
        }
        let name = merged_actor_name(name, |n| env.actor_pose(n).is_some());
        let got = env
            .actor_pose(name)
            .unwrap_or_else(|| panic!("{ctx}: no actor {name}"));
        assert!(
            max_abs(&got[..3], &pose[..3]) < 2e-6,
            "{ctx}: {name} position"
        );
        assert!(
            quat_angle(&got[3..], &pose[3..]) < 2e-6,
            "{ctx}: {name} rotation"
        );
    }
    let (p, mut q) = env.tcp_pose();
    assert!(max_abs(&p, &s.tcp_pose[..3]) < 2e-6, "{ctx}: tcp position");
    // PhysX negates a revolute joint's rotation once its angle passes π (the Panda's joint 6
    // reaches 3.2 rad in LiftPegUpright's motion-planning episodes): the TCP quaternion is
    // then the same rotation with the opposite sign, in `tcp_pose` and in the observation.
    let flipped = q
        .iter()
        .zip(&s.tcp_pose[3..])
        .map(|(a, b)| a * b)
        .sum::<f64>()
        < 0.0;
    if flipped {
        assert!(
            s.robot_qpos.iter().any(|a| a.abs() > std::f64::consts::PI),
            "{ctx}: TCP quaternion of the opposite sign with every joint within ±π"
        );
        q = q.map(|x| -x);
    }
    // Fetch's TCP quaternion is an unnormalised average in ManiSkill: compare as written.
    assert!(
        max_abs(&q, &s.tcp_pose[3..]) < 1e-5,
        "{ctx}: tcp quaternion {q:?} vs {:?}",
        &s.tcp_pose[3..]
    );
    let tcp_quat = env
        .obs_layout()
        .iter()
        .find(|(k, _)| k == "extra/tcp_pose")
        .map(|(_, r)| r.start + 3..r.end);
    let obs = env.obs();
    assert_eq!(obs.len(), s.obs_state.len(), "{ctx}: obs length");
    for (i, (a, b)) in obs.iter().zip(&s.obs_state).enumerate() {
        if Some(i) == grasp_obs {
            continue;
        }
        let sign = match &tcp_quat {
            Some(r) if flipped && r.contains(&i) => -1.0,
            _ => 1.0,
        };
        let a = sign * a;
        assert!(
            (a - b).abs() <= 2e-5 * (1.0 + b.abs()),
            "{ctx}: obs[{i}] {a} vs {b}"
        );
    }
    let info = env.info();
    let grasp_agrees = info.flag(grasp_key) == s.flag(grasp_key);
    for k in info.keys {
        if !env.info_is_flag(k) || (*k == grasp_key) || (*k == "success" && !grasp_agrees) {
            continue;
        }
        assert_eq!(info.flag(k), s.flag(k), "{ctx}: info {k}");
    }
    let unreported = UNREPORTED_GRASP.contains(&env.id());
    let angle_checked = ANGLE_GRASP_REWARD.contains(&env.id());
    if grasp_agrees && (contacts_agree || !unreported) && (fingers_free || !angle_checked) {
        let dense = env.dense_reward();
        assert!(
            (dense - s.reward_dense as f64).abs() < 1e-4 * (1.0 + dense.abs()),
            "{ctx}: dense reward {dense} vs {}",
            s.reward_dense
        );
    }
    grasp_agrees
}

#[test]
fn seeded_initial_states_equal_maniskills() {
    for f in files() {
        for ep in &f.episodes {
            let mut env =
                env_for(&f.env_id, &f.robot, &ep.control_mode, SimConfig::default()).unwrap();
            env.reset(Some(ep.seed));
            let ctx = format!("{} {} seed {}", f.env_id, f.robot, ep.seed);
            let key = env.grasp_info_key();
            // A fresh env's first reset sees no previous contacts: the grasp flag is false
            // in both.
            check_state_quantities(&env, &ep.initial, key, None, true, true, &ctx);
            assert_eq!(env.info().flag(key), ep.initial.flag(key), "{ctx}: grasp");
        }
    }
}

/// The position of the grasp flag in the flat `state` observation, if it is there.
fn grasp_obs_index(f: &RefFile, mode: &str) -> Option<usize> {
    f.control_modes[mode]
        .obs_state_layout
        .iter()
        .find(|(k, ..)| k == "extra.is_grasped")
        .map(|(_, a, _)| *a)
}

#[test]
fn obs_rewards_and_flags_on_maniskills_states_equal_maniskills() {
    for f in files() {
        let (mut steps, mut grasp_checked, mut grasp_agree) = (0, 0, 0);
        for ep in &f.episodes {
            let mut env =
                env_for(&f.env_id, &f.robot, &ep.control_mode, SimConfig::default()).unwrap();
            env.reset(Some(ep.seed));
            let key = env.grasp_info_key();
            let gi = grasp_obs_index(&f, &ep.control_mode);
            for s in &ep.steps {
                env.set_state_dict(&s.state_dict).unwrap();
                env.set_elapsed_steps(s.t);
                let ctx = format!("{} {} seed {} t {}", f.env_id, f.robot, ep.seed, s.t);
                // "Where contacts agree": both sims see the fingers touching the object or
                // both see them free.
                let touching_ms = [s.grasp_contact.finger1, s.grasp_contact.finger2]
                    .iter()
                    .map(|f| f.iter().map(|x| x * x).sum::<f64>().sqrt() > 0.5)
                    .collect::<Vec<_>>();
                let ff = env.finger_forces();
                let touching_mj = ff
                    .iter()
                    .map(|f| f.iter().map(|x| x * x).sum::<f64>().sqrt() > 0.5)
                    .collect::<Vec<_>>();
                let contacts_agree = touching_ms == touching_mj;
                let free = !touching_ms.iter().chain(&touching_mj).any(|&t| t);
                let agree = check_state_quantities(&env, s, key, gi, contacts_agree, free, &ctx);
                steps += 1;
                if contacts_agree {
                    grasp_checked += 1;
                    grasp_agree += agree as usize;
                }
            }
        }
        assert!(steps > 0);
        let rate = grasp_agree as f64 / grasp_checked.max(1) as f64;
        assert!(
            rate >= 0.99,
            "{} {}: grasp flag agrees on {grasp_agree} of {grasp_checked} states with agreeing contacts",
            f.env_id,
            f.robot
        );
    }
}

/// Measured agreement of open-loop replays (sim_freq 100) with ManiSkill's trajectories
/// (2026-11-29, after the drives became PhysX's sequential impulses):
/// mean joint (rad or m), TCP and object position (m) errors in the step buckets 1, 6–10 and
/// 26–50, then the one-step (re-synchronised every step) joint, TCP and object errors. A
/// pair passes when every figure is within 30 % of what was measured — tight enough that a
/// wrong drive gain, limit, armature or law shows (docs/physics.md; docs/agreement.md).
const MEASURED: [(&str, [f64; 12]); 22] = [
    (
        "PickCube-v1__fetch",
        [
            1.39e-03, 6.20e-03, 2.75e-02, 3.87e-04, 3.79e-03, 1.46e-02, 8.01e-07, 8.73e-07,
            9.63e-07, 2.86e-03, 7.64e-04, 4.87e-07,
        ],
    ),
    (
        "PickCube-v1__panda",
        [
            1.34e-04, 5.21e-04, 1.94e-03, 6.49e-05, 3.29e-04, 5.72e-04, 7.69e-07, 8.45e-07,
            2.09e-05, 3.52e-04, 1.36e-04, 2.58e-05,
        ],
    ),
    (
        "PickCube-v1__so100",
        [
            2.83e-04, 2.51e-04, 1.08e-03, 1.80e-05, 2.49e-05, 9.99e-05, 7.63e-07, 8.44e-07,
            1.05e-06, 6.46e-04, 4.47e-05, 4.63e-07,
        ],
    ),
    (
        "PickCube-v1__widowxai",
        [
            9.04e-05, 1.20e-04, 1.86e-03, 2.03e-05, 3.18e-05, 6.41e-04, 8.09e-07, 8.69e-07,
            8.81e-07, 6.38e-04, 1.80e-04, 4.84e-07,
        ],
    ),
    (
        "PickCube-v1__xarm6_robotiq",
        [
            1.15e-02, 5.74e-03, 1.87e-01, 6.33e-05, 1.24e-04, 1.00e-02, 7.87e-07, 8.64e-07,
            6.70e-03, 7.38e-02, 2.32e-03, 9.95e-04,
        ],
    ),
    (
        "PickCubeSO100-v1__so100",
        [
            2.83e-04, 2.51e-04, 1.08e-03, 1.80e-05, 2.49e-05, 9.99e-05, 7.63e-07, 8.44e-07,
            1.05e-06, 6.46e-04, 4.47e-05, 4.63e-07,
        ],
    ),
    (
        "PickCubeWidowXAI-v1__widowxai",
        [
            9.04e-05, 1.20e-04, 1.86e-03, 2.03e-05, 3.18e-05, 6.41e-04, 8.09e-07, 8.69e-07,
            8.81e-07, 6.38e-04, 1.80e-04, 4.84e-07,
        ],
    ),
    (
        "PlaceSphere-v1__fetch",
        [
            1.39e-03, 6.20e-03, 2.75e-02, 3.87e-04, 3.79e-03, 1.46e-02, 7.31e-07, 9.70e-07,
            9.71e-07, 2.86e-03, 7.64e-04, 7.24e-07,
        ],
    ),
    (
        "PlaceSphere-v1__panda",
        [
            1.34e-04, 5.24e-04, 2.01e-03, 6.49e-05, 3.32e-04, 5.72e-04, 7.31e-07, 9.71e-07,
            3.75e-05, 5.49e-04, 1.24e-04, 1.07e-04,
        ],
    ),
    (
        "PokeCube-v1__fetch",
        [
            1.39e-03, 6.20e-03, 2.77e-02, 3.87e-04, 3.79e-03, 1.45e-02, 1.10e-06, 1.17e-06,
            3.17e-03, 2.89e-03, 8.17e-04, 1.82e-04,
        ],
    ),
    (
        "PokeCube-v1__panda",
        [
            1.34e-04, 5.27e-04, 2.09e-03, 6.49e-05, 3.34e-04, 6.08e-04, 1.09e-06, 1.18e-06,
            7.70e-05, 1.18e-03, 2.90e-04, 3.57e-04,
        ],
    ), // PushCube and PullCube: 2026-11-29, from tests/data/maniskill/record_push_pull.py's files.
    (
        "PushCube-v1__fetch",
        [
            1.39e-03, 6.20e-03, 2.75e-02, 3.87e-04, 3.79e-03, 1.46e-02, 9.22e-07, 9.89e-07,
            9.88e-07, 2.86e-03, 7.64e-04, 5.05e-07,
        ],
    ),
    (
        "PushCube-v1__panda",
        [
            1.37e-04, 5.86e-04, 2.01e-03, 6.49e-05, 3.27e-04, 5.80e-04, 9.20e-07, 9.88e-07,
            3.40e-04, 9.49e-04, 2.94e-04, 6.25e-04,
        ],
    ),
    (
        "PullCube-v1__fetch",
        [
            1.39e-03, 6.20e-03, 2.75e-02, 3.87e-04, 3.79e-03, 1.46e-02, 9.22e-07, 9.89e-07,
            9.88e-07, 2.86e-03, 7.64e-04, 5.05e-07,
        ],
    ),
    (
        "PullCube-v1__panda",
        [
            1.37e-04, 5.86e-04, 3.46e-03, 6.49e-05, 3.27e-04, 1.72e-03, 9.20e-07, 9.88e-07,
            2.78e-03, 1.46e-03, 5.54e-04, 1.03e-03,
        ],
    ),
    // StackCube: 2026-11-29, from record_push_pull.py's files.
    (
        "StackCube-v1__fetch",
        [
            1.39e-03, 6.20e-03, 2.75e-02, 3.87e-04, 3.79e-03, 1.46e-02, 8.95e-07, 9.70e-07,
            9.72e-07, 2.86e-03, 7.64e-04, 5.22e-07,
        ],
    ),
    (
        "StackCube-v1__panda",
        [
            1.34e-04, 5.34e-04, 1.95e-03, 6.49e-05, 3.38e-04, 5.73e-04, 9.04e-07, 9.75e-07,
            8.04e-06, 3.58e-04, 1.28e-04, 3.96e-05,
        ],
    ),
    // StackCube with the panda_wristcam (2026-11-30): the Panda's figures, episode for
    // episode, but for one motion-planning episode (seed 1202: one-step joint error 4.6e-3,
    // the Panda's 2.7e-4), which doubles the mean.
    (
        "StackCube-v1__panda_wristcam",
        [
            1.35e-04, 5.64e-04, 2.87e-03, 6.36e-05, 3.61e-04, 7.17e-04, 9.04e-07, 9.75e-07,
            3.67e-04, 7.17e-04, 1.90e-04, 2.16e-04,
        ],
    ),
    // LiftPegUpright: 2026-11-29, from record_push_pull.py's files.
    (
        "LiftPegUpright-v1__fetch",
        // Object error of steps 26–50: 1.42e-3 before the scene's no-slip pass (1 December
        // 2026; LiftPegUpright's NOSLIP_ITERATIONS): the smooth walks push the lying peg along
        // the table, where static friction holds it a little longer than PhysX's (the
        // one-step object error is unchanged; docs/physics.md, "Static friction").
        [
            1.39e-03, 6.20e-03, 2.78e-02, 3.87e-04, 3.79e-03, 1.46e-02, 1.09e-06, 1.15e-06,
            3.12e-03, 2.88e-03, 7.91e-04, 1.43e-04,
        ],
    ),
    (
        "LiftPegUpright-v1__panda",
        [
            1.34e-04, 5.20e-04, 1.94e-03, 6.49e-05, 3.29e-04, 5.71e-04, 1.09e-06, 1.16e-06,
            6.06e-06, 9.49e-04, 2.48e-04, 5.27e-04,
        ],
    ),
    // PushT (2026-11-29): the stick starts 1-2 cm above the table and the random actions
    // press it into the table and the T, where PhysX's and MuJoCo's contacts part (one-step
    // joint error 2.4e-3 rad with the tip above 3 cm, 1.5e-2 below); the T drops the 1 mm
    // it spawns above the table, PhysX stopping it dead at step 1, MuJoCo 0.8 mm lower.
    (
        "PushT-v1__panda_stick",
        [
            3.13e-04, 9.91e-03, 1.75e-01, 1.42e-04, 9.06e-04, 2.77e-02, 8.19e-04, 2.49e-05,
            1.44e-03, 8.62e-03, 1.20e-03, 3.48e-05,
        ],
    ),
    // PegInsertionSide (2026-11-30): random, smooth-walk and ManiSkill's motion-planning
    // episodes (the held peg pushed into the box's walls in the last).
    (
        "PegInsertionSide-v1__panda_wristcam",
        [
            1.37e-04, 5.81e-04, 5.17e-02, 6.32e-05, 3.72e-04, 5.47e-03, 7.29e-07, 8.30e-07,
            1.79e-05, 5.23e-03, 6.59e-04, 2.04e-04,
        ],
    ),
];

const NAMES: [&str; 12] = [
    "joint@1",
    "joint@6-10",
    "joint@26-50",
    "tcp@1",
    "tcp@6-10",
    "tcp@26-50",
    "obj@1",
    "obj@6-10",
    "obj@26-50",
    "one-step joint",
    "one-step tcp",
    "one-step obj",
];

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n.max(1) as f64
}

/// The twelve figures of [`MEASURED`] for one file.
fn agreement(f: &RefFile) -> [f64; 12] {
    let open = replay_file(f, FidelityOptions::default()).unwrap();
    let one = replay_file(
        f,
        FidelityOptions {
            resync: Some(1),
            ..Default::default()
        },
    )
    .unwrap();
    let bucket = |from: u32, k: fn(&StepError) -> f64| {
        mean(open.episodes.iter().flat_map(|e| {
            e.per_step
                .iter()
                .enumerate()
                .filter(move |(i, _)| {
                    let t = *i as u32 + 1;
                    match from {
                        1 => t == 1,
                        6 => (6..=10).contains(&t),
                        _ => (26..=50).contains(&t),
                    }
                })
                .map(move |(_, s)| k(s))
        }))
    };
    let all =
        |k: fn(&StepError) -> f64| mean(one.episodes.iter().flat_map(|e| e.per_step.iter().map(k)));
    [
        bucket(1, |s| s.joint),
        bucket(6, |s| s.joint),
        bucket(26, |s| s.joint),
        bucket(1, |s| s.tcp_pos),
        bucket(6, |s| s.tcp_pos),
        bucket(26, |s| s.tcp_pos),
        bucket(1, |s| s.obj_pos),
        bucket(6, |s| s.obj_pos),
        bucket(26, |s| s.obj_pos),
        all(|s| s.joint),
        all(|s| s.tcp_pos),
        all(|s| s.obj_pos),
    ]
}

#[test]
fn open_loop_replay_tracks_maniskill_within_the_measured_agreement() {
    let mut failures = Vec::new();
    for f in files() {
        let name = format!("{}__{}", f.env_id, f.robot);
        let want = MEASURED.iter().find(|(n, _)| *n == name).unwrap().1;
        let got = agreement(&f);
        // The figures as MEASURED spells them, for an intended change (--nocapture).
        let figures: Vec<String> = got.iter().map(|x| format!("{x:.2e}")).collect();
        println!("(\"{name}\", [{}]),", figures.join(", "));
        for k in 0..12 {
            if got[k] > 1.3 * want[k] {
                failures.push(format!(
                    "{name} {}: {:.3e} > 1.3 × {:.3e}",
                    NAMES[k], got[k], want[k]
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn motion_planning_episodes_succeed_where_maniskills_did() {
    for f in files().into_iter().filter(|f| f.robot == "panda") {
        let report = replay_file(&f, FidelityOptions::default()).unwrap();
        for (e, ep) in report.episodes.iter().zip(&f.episodes) {
            if ep.source != "motion_planning" {
                continue;
            }
            let ctx = format!("{} seed {}", f.env_id, ep.seed);
            if f.env_id == "PushCube-v1" {
                // ManiSkill's own push solution stops the TCP 12 cm short of the goal centre:
                // its cube ends 8.2–9.4 cm from the centre, within 2 cm of the 10 cm success
                // radius, so the 2–3 cm by which the two simulators' pushed cubes part decide
                // the outcome (mjskill: 1 of the 4 episodes succeeds; docs/outcome-physics.md).
                // Compared here: the cube never strays more than the measured 6.3 cm.
                let last = ep.steps.last().unwrap();
                let (c, g) = (last.actors["cube"], last.actors["goal_region"]);
                let margin = 0.1 - (c[0] - g[0]).hypot(c[1] - g[1]);
                assert!(
                    (0.0..0.02).contains(&margin),
                    "{ctx}: ManiSkill's margin {margin}"
                );
                let worst = e.per_step.iter().map(|s| s.obj_pos).fold(0.0, f64::max);
                assert!(worst < 0.07, "{ctx}: the cubes part by {worst} m");
            } else if f.env_id == "PlaceSphere-v1" {
                // PlaceSphere's `success` also needs the released sphere to be still. In
                // ManiSkill it stops within a step of landing between the bin's wall edges;
                // in MuJoCo it can keep rocking there for a while (docs/physics.md), so for
                // this task the placement itself is compared: the sphere never strays 1 cm
                // from ManiSkill's.
                assert_eq!(e.first_object_divergence, None, "{ctx}: sphere placement");
            } else {
                assert_eq!(e.ever_success.0, e.ever_success.1, "{ctx}: success reached");
                assert_eq!(
                    e.reference_success, e.mjskill_success,
                    "{ctx}: final success"
                );
            }
        }
    }
}

/// Held-state figures per file, as measured: (file, states where ManiSkill's grasp flag is
/// true, of those the ones where mjskill's flag is true when the state is imported with the
/// drive targets of the action that led to it, states (of all) whose grasp flag differs,
/// the largest dense-reward difference over all states). With a plain `set_state_dict`
/// (no drive targets) mjskill's flag was false on every one of the held states.
const HELD: [(&str, usize, usize, usize, f64); 22] = [
    ("PickCube-v1__fetch", 0, 0, 0, 1.75e-6),
    ("PickCube-v1__panda", 130, 130, 0, 2.01e-6),
    ("PickCube-v1__so100", 0, 0, 0, 6.44e-7),
    ("PickCube-v1__widowxai", 0, 0, 0, 5.25e-7),
    // One smooth-walk state where the Robotiq fingers touch the cube's edge.
    ("PickCube-v1__xarm6_robotiq", 1, 0, 1, 1.34),
    ("PickCubeSO100-v1__so100", 0, 0, 0, 6.44e-7),
    ("PickCubeWidowXAI-v1__widowxai", 0, 0, 0, 5.25e-7),
    ("PlaceSphere-v1__fetch", 0, 0, 0, 4.14e-6),
    ("PlaceSphere-v1__panda", 232, 232, 0, 3.89e-6),
    ("PokeCube-v1__fetch", 0, 0, 0, 3.09e-6),
    ("PokeCube-v1__panda", 1865, 1865, 0, 6.04e-6),
    // PushCube and PullCube report no grasp flag; the rewards of every state.
    ("PushCube-v1__fetch", 0, 0, 0, 2.06e-6),
    ("PushCube-v1__panda", 0, 0, 0, 1.81e-6),
    ("PullCube-v1__fetch", 0, 0, 0, 1.46e-6),
    ("PullCube-v1__panda", 0, 0, 0, 2.25e-6),
    // StackCube: 2026-11-29, grasp flag `is_cubeA_grasped` (the Fetch's files hold no grasp).
    ("StackCube-v1__fetch", 0, 0, 0, 2.88e-6),
    ("StackCube-v1__panda", 224, 224, 0, 3.53e-6),
    ("StackCube-v1__panda_wristcam", 189, 189, 0, 4.75e-6),
    // LiftPegUpright: 2026-11-29. No grasp flag in `info`, but the reward checks the grasp:
    // with the drive targets restored it agrees on every state.
    ("LiftPegUpright-v1__fetch", 0, 0, 0, 3.36e-7),
    ("LiftPegUpright-v1__panda", 0, 0, 0, 3.39e-7),
    // PushT: 2026-11-29. The panda_stick has no fingers: no grasp, rewards of every state.
    ("PushT-v1__panda_stick", 0, 0, 0, 2.43e-7),
    // PegInsertionSide: 2026-11-30. No grasp flag in `info`; the reward's 20° grasp check
    // parts on the held states of the motion-planning episodes (ANGLE_GRASP_REWARD).
    ("PegInsertionSide-v1__panda_wristcam", 0, 0, 0, 7.84),
];

/// ManiSkill's recorded states lack the drive targets that PhysX keeps from the last action;
/// imported with the targets of the action that led to them
/// (`Env::set_state_dict_after_action`), held objects stay squeezed, so `is_grasped` and the
/// dense reward evaluate as in ManiSkill. A plain `set_state_dict` (the drives hold the
/// imported positions) loses every grasp.
#[test]
fn held_states_imported_with_the_actions_drive_targets_evaluate_as_in_maniskill() {
    let mut failures = Vec::new();
    for f in files() {
        let name = format!("{}__{}", f.env_id, f.robot);
        let (mut held, mut held_mj, mut differ, mut max_reward, mut held_plain) =
            (0, 0, 0, 0.0f64, 0);
        for ep in &f.episodes {
            let mut env =
                env_for(&f.env_id, &f.robot, &ep.control_mode, SimConfig::default()).unwrap();
            let mut plain =
                env_for(&f.env_id, &f.robot, &ep.control_mode, SimConfig::default()).unwrap();
            env.reset(Some(ep.seed));
            let key = env.grasp_info_key();
            for s in &ep.steps {
                env.set_state_dict_after_action(s.action.as_deref().unwrap(), &s.state_dict)
                    .unwrap();
                env.set_elapsed_steps(s.t);
                plain.set_state_dict(&s.state_dict).unwrap();
                let (ms, mj) = (s.flag(key), env.info().flag(key));
                held += ms as usize;
                held_mj += (ms && mj) as usize;
                held_plain += (ms && plain.info().flag(key)) as usize;
                differ += (ms != mj) as usize;
                max_reward = max_reward.max((env.dense_reward() - s.reward_dense as f64).abs());
            }
        }
        let want = HELD.iter().find(|h| h.0 == name).unwrap();
        let got = format!("{name}: held {held}, grasped in mjskill {held_mj}, flag differs {differ}, max |Δ dense| {max_reward:.2e}, plain import grasped {held_plain}");
        if held != want.1
            || held_mj < want.2
            || differ > want.3
            || max_reward > 1.3 * want.4
            || held_plain != 0
        {
            failures.push(format!("{got}; measured {want:?}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// LiftPegUpright's static friction (docs/physics.md, "Static friction"): ManiSkill's four
/// motion-planning episodes grip the lying peg loosely and lift it; PhysX's peg pivots in the
/// grip while the table drags its far end, then holds while the hand holds still. Replayed
/// open loop, mjskill's peg follows PhysX's from step 26 to the end within 12–31 mm (mean)
/// and 0.20–0.50 rad (worst step) with the scene's no-slip pass; without it the peg crept
/// round in the grip under gravity: 18–43 mm and 0.48–0.60 rad.
#[test]
fn the_loosely_held_peg_holds_in_the_grip_as_physxs_does() {
    let f = RefFile::open(&data_dir().join("LiftPegUpright-v1__panda.json.gz"))
        .unwrap_or_else(|err| panic!("{err}"));
    let report = replay_file(&f, FidelityOptions::default()).unwrap();
    let mut seen = 0;
    for e in report
        .episodes
        .iter()
        .filter(|e| e.source.starts_with("motion"))
    {
        let late = &e.per_step[25..];
        let pos = mean(late.iter().map(|s| s.obj_pos));
        let rot = late.iter().map(|s| s.obj_rot).fold(0.0, f64::max);
        println!("seed {}: mean {pos:.4} m, worst {rot:.3} rad", e.seed);
        assert!(
            pos < 0.035 && rot < 0.54,
            "seed {}: {pos} m, {rot} rad",
            e.seed
        );
        seen += 1;
    }
    assert_eq!(seen, 4, "ManiSkill's four motion-planning episodes");
}

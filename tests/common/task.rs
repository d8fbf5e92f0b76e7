//! What the task tests share (tests/push_pull_cube.rs, tests/stack_cube.rs): the env in the
//! dense reward mode, ManiSkill's recorded initial states (tests/data/maniskill_initial/),
//! and the small vector helpers of their spec reward formulas.
use std::collections::BTreeMap;
use std::path::PathBuf;

use mjskill::maniskill::merged_actor_name;
use mjskill::{make, Env, EnvConfig, ObsMode, RewardMode};
use serde::Deserialize;

/// The bound on the seeded `state` observation (max |diff|).
pub const OBS_TOL: f64 = 1e-4;

/// `id` with `robot` in `obs_mode`, dense rewards.
pub fn env(id: &str, robot: &str, obs_mode: ObsMode) -> Env {
    make(
        id,
        EnvConfig {
            robot: Some(robot.into()),
            obs_mode,
            reward_mode: RewardMode::Dense,
            ..Default::default()
        },
    )
    .unwrap()
}

/// One seed's initial state as ManiSkill recorded it.
#[derive(Deserialize)]
pub struct Initial {
    pub obs_state: Vec<f64>,
    pub actors: BTreeMap<String, [f64; 7]>,
    pub tcp_pose: [f64; 7],
    pub robot_qpos: Vec<f64>,
    pub info: BTreeMap<String, bool>,
    pub reward_dense: f64,
    pub reward_normalized: f64,
}

/// A pair's file of initial states (tests/data/maniskill_initial/record.py).
#[derive(Deserialize)]
pub struct InitialFile {
    pub env_id: String,
    pub robot: String,
    pub control_mode: String,
    pub obs_state_layout: Vec<(String, usize, usize)>,
    pub seeds: BTreeMap<String, Vec<u64>>,
    pub episodes: BTreeMap<String, Initial>,
}

/// The initial states of (`id`, `robot`), checked to be that pair's.
pub fn initial_file(id: &str, robot: &str) -> InitialFile {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/maniskill_initial")
        .join(format!("{id}__{robot}.json"));
    let f: InitialFile = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    assert_eq!((f.env_id.as_str(), f.robot.as_str()), (id, robot));
    f
}

/// The env's flat `state` layout is ManiSkill's recorded `obs_state_layout`, key for key
/// (`agent.qpos` is mjskill's `agent/qpos`).
pub fn check_layout(e: &Env, layout: &[(String, usize, usize)], what: &str) {
    let want: Vec<(String, usize, usize)> = layout
        .iter()
        .map(|(k, a, b)| (k.replace('.', "/"), *a, *b))
        .collect();
    let got: Vec<(String, usize, usize)> = e
        .obs_layout()
        .iter()
        .map(|(k, r)| (k.clone(), r.start, r.end))
        .collect();
    assert_eq!(got, want, "{what}: layout");
}

/// The env's actors are at ManiSkill's recorded poses (within 2e-6), under their merged names
/// (`mjskill::maniskill::merged_actor_name`).
pub fn check_actor_poses(e: &Env, actors: &BTreeMap<String, [f64; 7]>, ctx: &str) {
    for (name, pose) in actors {
        let name = merged_actor_name(name, |n| e.actor_pose(n).is_some());
        let got = e
            .actor_pose(name)
            .unwrap_or_else(|| panic!("{ctx}: {name}"));
        assert!(
            max_abs(got, pose) < 2e-6,
            "{ctx}: {name} {got:?} vs {pose:?}"
        );
    }
}

/// Mass, principal moments and centre of mass (link frame) SAPIEN gives a link or an actor
/// (record.py's `links`).
#[derive(Deserialize)]
pub struct Link {
    pub mass: f64,
    pub inertia: [f64; 3],
    pub cmass: [f64; 7],
}

/// Every body in `links` weighs in the env's model what SAPIEN gives it: mass, centre of mass
/// and principal moments (as sets: the two sims may order the axes differently). Links
/// without shapes get SAPIEN's token mass and mjskill none: they are skipped.
pub fn check_links(e: &Env, links: &BTreeMap<String, Link>) {
    let m = e.model();
    for (name, link) in links {
        if link.mass < 1e-3 {
            continue;
        }
        let b = m.require_body(name).unwrap().index();
        let mass = m.body_mass()[b];
        assert!(
            (mass - link.mass).abs() < 1e-5 * link.mass,
            "{name}: mass {mass}"
        );
        let ipos = &m.body_ipos()[3 * b..3 * b + 3];
        for k in 0..3 {
            assert!(
                (ipos[k] - link.cmass[k]).abs() < 2e-5,
                "{name}: com {ipos:?}"
            );
        }
        let mut got = m.body_inertia()[3 * b..3 * b + 3].to_vec();
        let mut want = link.inertia.to_vec();
        got.sort_by(f64::total_cmp);
        want.sort_by(f64::total_cmp);
        for k in 0..3 {
            assert!(
                (got[k] - want[k]).abs() < 1e-4 * want[2],
                "{name}: inertia {got:?} vs {want:?}"
            );
        }
    }
}

/// max |a − b| over two sequences of the same length.
pub fn max_abs(a: impl IntoIterator<Item = f64>, b: &[f64]) -> f64 {
    let a: Vec<f64> = a.into_iter().collect();
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// The observation layout's `extra/...` keys, in order (a task's observation extras).
pub fn extra_keys(e: &Env) -> Vec<&str> {
    e.obs_layout()
        .iter()
        .map(|(k, _)| k.as_str())
        .filter(|k| k.starts_with("extra/"))
        .collect()
}

/// A flat observation part as f64.
pub fn part(e: &Env, key: &str) -> Vec<f64> {
    e.obs_part(key)
        .unwrap_or_else(|| panic!("no {key}"))
        .iter()
        .map(|&x| x as f64)
        .collect()
}

/// Euclidean norm.
pub fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// a − b, element-wise.
pub fn sub(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

/// `1 − tanh(5 d)`.
pub fn closeness(d: f64) -> f64 {
    1.0 - (5.0 * d).tanh()
}

/// Checks (`id`, `robot`)'s seeded resets against ManiSkill's recorded initial states, every
/// seed of every split (fitted and held out, 50 each): the `state` layout key for key, the
/// observation within [`OBS_TOL`], the actors' poses, the TCP pose, the joints, the info
/// (keys `keys`, every recorded value) and the dense and normalised rewards (`max_reward`);
/// with `actors`, that many actors recorded. Prints the worst observation difference per
/// split.
pub fn check_initial_states(
    id: &str,
    robot: &str,
    keys: &[&str],
    max_reward: f64,
    actors: Option<usize>,
) {
    let f = initial_file(id, robot);
    let mut e = env(id, robot, ObsMode::State);
    assert_eq!(e.control_mode(), f.control_mode);
    check_layout(&e, &f.obs_state_layout, &format!("{id} {robot}"));
    for (split, seeds) in &f.seeds {
        assert_eq!(seeds.len(), 50, "{id} {robot} {split}");
        let mut worst = 0.0f64;
        for seed in seeds {
            let ms = &f.episodes[&seed.to_string()];
            let ctx = format!("{id} {robot} seed {seed}");
            e.reset(Some(*seed));
            let obs = e.obs().iter().map(|&x| x as f64);
            let d = max_abs(obs, &ms.obs_state);
            worst = worst.max(d);
            assert!(d <= OBS_TOL, "{ctx}: state obs max |diff| {d}");
            assert!(!ms.actors.is_empty(), "{ctx}: no actors recorded");
            if let Some(n) = actors {
                assert_eq!(ms.actors.len(), n, "{ctx}: actors recorded");
            }
            check_actor_poses(&e, &ms.actors, &ctx);
            let (p, q) = e.tcp_pose();
            let tcp = p.into_iter().chain(q);
            assert!(max_abs(tcp, &ms.tcp_pose) < 1e-5, "{ctx}: tcp_pose");
            assert!(
                max_abs(e.robot_qpos(), &ms.robot_qpos) < 1e-6,
                "{ctx}: qpos"
            );
            assert_eq!(e.info().keys, keys, "{ctx}");
            for (k, &v) in &ms.info {
                assert_eq!(e.info().get(k), Some(v as u8 as f64), "{ctx}: {k}");
            }
            let dense = e.dense_reward();
            assert!(
                (dense - ms.reward_dense).abs() < 1e-5,
                "{ctx}: dense {dense} vs {}",
                ms.reward_dense
            );
            assert!(
                (dense / max_reward - ms.reward_normalized).abs() < 1e-5,
                "{ctx}"
            );
        }
        eprintln!("{id} {robot} {split}: max |obs − ManiSkill| = {worst:.2e}");
    }
}

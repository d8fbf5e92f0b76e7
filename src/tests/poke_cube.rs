//! PokeCube-v1 with the Panda: seeding, layout, the goal target, the upstream quirks of the
//! observation and `evaluate()`, and every dense-reward stage on constructed states.

use super::common;

use std::f64::consts::FRAC_1_SQRT_2;

use common::{close, norm, part, put_free_body as put, set_robot_qvel};

use crate::env::{make, Env, EnvConfig, RewardMode};
use crate::mujoco::ObjType;

fn env_with(control_mode: Option<&str>) -> Env {
    make(
        "PokeCube-v1",
        EnvConfig {
            reward_mode: RewardMode::Dense,
            control_mode: control_mode.map(str::to_string),
            ..Default::default()
        },
    )
    .unwrap()
}

fn rotz(yaw: f64) -> [f64; 4] {
    [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()]
}

#[test]
fn seeded_resets_reproduce_maniskills_initial_states() {
    // docs/tasks.md §5 (PokeCube rows).
    let mut e = env_with(None);
    for (seed, qpos, peg, cube, cube_q, goal) in [
        (
            0u64,
            [
                0.035281, 0.400702, 0.019575, -1.918678, 0.037351, 2.336649, 0.8044, 0.04, 0.04,
            ],
            [-0.000749, 0.053644, 0.025],
            [0.219251, -0.038515, 0.02],
            [0.99973, 0.0, 0.0, -0.023231],
            [0.319251, -0.038515, 0.001],
        ),
        (
            1,
            [
                0.032487, 0.380464, -0.010563, -1.984955, 0.017308, 2.310164, 0.820294, 0.04, 0.04,
            ],
            [0.051526, -0.044138, 0.025],
            [0.271526, -0.094144, 0.02],
            [0.999338, 0.0, 0.0, 0.036387],
            [0.371526, -0.094144, 0.001],
        ),
    ] {
        e.reset(Some(seed));
        close(e.obs_part("agent/qpos").unwrap(), &qpos, 2e-6, "qpos");
        let peg_pose = e.obs_part("extra/peg_pose").unwrap();
        close(&peg_pose[..3], &peg, 2e-6, "peg");
        close(&peg_pose[3..], &[1.0, 0.0, 0.0, 0.0], 1e-7, "peg q");
        let cube_pose = e.obs_part("extra/cube_pose").unwrap();
        close(&cube_pose[..3], &cube, 2e-6, "cube");
        close(&cube_pose[3..], &cube_q, 2e-6, "cube q");
        // The goal region itself (not in the observation): its body pose is upstream's.
        let model = e.model().clone();
        let g = model.require_id(ObjType::Body, "goal_region").unwrap();
        let p: Vec<f32> = e.data().xpos()[3 * g..3 * g + 3]
            .iter()
            .map(|&x| x as f32)
            .collect();
        close(&p, &goal, 2e-6, "goal");
        let q: Vec<f32> = e.data().xquat()[4 * g..4 * g + 4]
            .iter()
            .map(|&x| x as f32)
            .collect();
        close(
            &q,
            &[FRAC_1_SQRT_2, 0.0, FRAC_1_SQRT_2, 0.0],
            1e-6,
            "goal q",
        );
        // cube_to_goal_pos = goal − cube.
        let c2g: Vec<f64> = goal.iter().zip(cube).map(|(g, c)| g - c).collect();
        close(
            e.obs_part("extra/cube_to_goal_pos").unwrap(),
            &c2g,
            4e-6,
            "c2g",
        );
    }
}

#[test]
fn state_layout_is_54_long_in_maniskills_order() {
    let e = env_with(None);
    assert_eq!(e.observation_space().shape, vec![54]);
    let layout: Vec<(&str, usize)> = e
        .obs_layout()
        .iter()
        .map(|(k, r)| (k.as_str(), r.len()))
        .collect();
    assert_eq!(
        layout,
        [
            ("agent/qpos", 9),
            ("agent/qvel", 9),
            ("extra/tcp_pose", 7),
            ("extra/cube_pose", 7),
            ("extra/peg_pose", 7),
            ("extra/goal_pos", 3),
            ("extra/tcp_to_peg_pos", 3),
            ("extra/peg_to_cube_pos", 3),
            ("extra/cube_to_goal_pos", 3),
            ("extra/peghead_to_cube_pos", 3),
        ]
    );
    // Without state only the TCP pose is an extra (the other keys are privileged).
    assert_eq!(e.extra_layout(false), vec![("tcp_pose".to_string(), 7)]);
    assert_eq!(
        e.info().keys,
        &[
            "success",
            "is_cube_placed",
            "is_peg_cube_fit",
            "is_peg_grasped",
            "angle_diff",
            "head_to_cube_dist"
        ]
    );
    let reg = crate::env::registry();
    let r = reg.iter().find(|r| r.id == "PokeCube-v1").unwrap();
    assert_eq!(r.default_robot, "panda");
    assert_eq!(r.max_episode_steps, 50);
    // pd_ee_delta_pos: the same 54 (no controller state).
    assert_eq!(
        env_with(Some("pd_ee_delta_pos")).observation_space().shape,
        vec![54]
    );
}

#[test]
fn scene_has_upstream_masses_and_a_visible_flat_target() {
    let e = env_with(None);
    let m = e.model().clone();
    let body = |n: &str| m.require_id(ObjType::Body, n).unwrap();
    let mass = m.body_mass()[body("cube")];
    assert!((mass - 0.064).abs() < 1e-12, "{mass}");
    assert!((m.body_mass()[body("peg")] - 0.6).abs() < 1e-9);
    // Peg inertia diag (0.00025, 0.003005, 0.003005) (MuJoCo orders the principal axes).
    let mut i = m.body_inertia()[3 * body("peg")..3 * body("peg") + 3].to_vec();
    i.sort_by(f64::total_cmp);
    for (got, want) in i.iter().zip([0.00025, 0.003005, 0.003005]) {
        assert!((got - want).abs() < 1e-9, "{i:?}");
    }
    // Five cylinders, none colliding, all in the group sensor cameras draw (0), lying flat:
    // the world z extent of each is its (tiny) half length. They only draw, so they are in
    // the render model, not in the physics model.
    let goal = body("goal_region");
    let of_goal = |m: &crate::mujoco::Model| -> Vec<usize> {
        (0..m.ngeom())
            .filter(|&g| m.geom_bodyid()[g] as usize == goal)
            .collect()
    };
    assert!(of_goal(&m).is_empty());
    let mut e = e;
    e.render().unwrap();
    let m = e.render_model().unwrap().clone();
    let geoms = of_goal(&m);
    assert_eq!(geoms.len(), 5);
    let d = e.data();
    // The body's orientation from the physics state, the geoms' own from the render model.
    let body_mat = &d.xmat()[9 * goal..9 * goal + 9];
    for (k, &g) in geoms.iter().enumerate() {
        assert_eq!(m.geom_contype()[g], 0);
        assert_eq!(m.geom_conaffinity()[g], 0);
        assert_eq!(m.geom_group()[g], 0);
        let size = &m.geom_size()[3 * g..3 * g + 2];
        assert!((size[0] - 0.05 * (5 - k) as f64 / 5.0).abs() < 1e-12);
        assert!((size[1] - (0.5e-5 + k as f64 * 1e-5)).abs() < 1e-15);
        // Cylinder axis (local z column of the geom frame) points along world ±z.
        let q = &m.geom_quat()[4 * g..4 * g + 4];
        let axis = [
            2.0 * (q[1] * q[3] + q[0] * q[2]),
            2.0 * (q[2] * q[3] - q[0] * q[1]),
            1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2]),
        ];
        let world_z: f64 = (0..3).map(|c| body_mat[6 + c] * axis[c]).sum();
        assert!(world_z.abs() > 1.0 - 1e-6, "ring {k} not flat: {axis:?}");
    }
}

fn reach_reward(d: f64) -> f64 {
    2.0 * (1.0 - (5.0 * d).tanh())
}

fn yaw_of(q: &[f64]) -> f64 {
    // atan2(−R01, R00)
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    (2.0 * (w * z - x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// Drives the TCP (pd_ee_delta_pos) to the peg centre from above and closes the gripper.
fn grasp_peg_centre(e: &mut Env) {
    let mut phase = 0;
    for _ in 0..60 {
        let tcp = part(e, "extra/tcp_pose");
        let peg = part(e, "extra/peg_pose");
        let (target, grip) = match phase {
            0 => ([peg[0], peg[1], peg[2] + 0.05], 1.0),
            1 => ([peg[0], peg[1], peg[2]], 1.0),
            _ => ([peg[0], peg[1], peg[2]], -1.0),
        };
        let err: Vec<f64> = (0..3).map(|k| target[k] - tcp[k]).collect();
        if phase == 0 && norm(&err) < 0.01 || phase == 1 && norm(&err) < 0.003 {
            phase += 1;
        }
        let mut a = [0f32; 4];
        for k in 0..3 {
            a[k] = (err[k] / 0.1).clamp(-1.0, 1.0) as f32;
        }
        a[3] = grip;
        e.step(&a).unwrap();
        if phase >= 2 {
            phase += 1;
            if phase > 8 && e.info().flag("is_peg_grasped") {
                return;
            }
        }
    }
    panic!("peg not grasped: {:?}", e.info());
}

#[test]
fn reward_stages_follow_the_spec() {
    let mut e = env_with(Some("pd_ee_delta_pos"));
    e.reset(Some(4));
    // Stage 1 (not grasped): 2·(1 − tanh(5·‖tcp − peg‖)), the TCP being far from the peg.
    let s = e.step(&[0.0; 4]).unwrap();
    assert!(!s.info.flag("is_peg_grasped") && !s.info.flag("is_cube_placed"));
    let d = norm(&part(&e, "extra/tcp_to_peg_pos"));
    assert!(d > 0.05);
    assert!((e.dense_reward() - reach_reward(d)).abs() < 1e-5);
    assert!(e.dense_reward() < 2.0);

    // Stage 2: grasped at the peg centre (reached: d < 0.01) ⇒ 4 + close + align.
    grasp_peg_centre(&mut e);
    let info = e.info().clone();
    let d = norm(&part(&e, "extra/tcp_to_peg_pos"));
    assert!(d < 0.01, "reached: {d}");
    assert!(info.flag("is_peg_grasped") && !info.flag("is_peg_cube_fit"));
    let h2c = info.get("head_to_cube_dist").unwrap();
    let angle = info.get("angle_diff").unwrap();
    // head_to_cube_dist is the xy part of peghead_to_cube_pos; angle_diff the yaw difference.
    let ph = part(&e, "extra/peghead_to_cube_pos");
    assert!((h2c - norm(&ph[..2])).abs() < 1e-6);
    let (peg_q, cube_q) = (part(&e, "extra/peg_pose"), part(&e, "extra/cube_pose"));
    assert!((angle - (yaw_of(&peg_q[3..]) - yaw_of(&cube_q[3..])).abs()).abs() < 1e-5);
    let want = 4.0 + (1.0 - (5.0 * h2c).tanh()) + (1.0 - (5.0 * angle).tanh());
    assert!(
        (e.dense_reward() - want).abs() < 1e-9,
        "{}",
        e.dense_reward()
    );
    assert!(e.dense_reward() > 4.0 && e.dense_reward() < 6.0);

    // Stage 3: the cube fitted against the (still grasped) peg's head, away from the goal
    // ⇒ 7 + place, place = 1 − tanh(5·‖goal − cube‖) (3-D).
    let peg = part(&e, "extra/peg_pose");
    let goal: Vec<f64> = {
        let (c, c2g) = (
            part(&e, "extra/cube_pose"),
            part(&e, "extra/cube_to_goal_pos"),
        );
        (0..3).map(|k| c[k] + c2g[k]).collect()
    };
    let peg_yaw = yaw_of(&peg[3..]);
    let cube = [peg[0] + 0.12 + 0.01, peg[1], 0.02];
    put(&mut e, "cube", cube, rotz(peg_yaw + 0.03));
    let info = e.info().clone();
    assert!(
        info.flag("is_peg_grasped") && info.flag("is_peg_cube_fit"),
        "{info:?}"
    );
    assert!(!info.flag("is_cube_placed"));
    assert!((info.get("head_to_cube_dist").unwrap() - 0.01).abs() < 1e-6);
    assert!((info.get("angle_diff").unwrap() - 0.03).abs() < 1e-6);
    let dist = norm(&[goal[0] - cube[0], goal[1] - cube[1], goal[2] - cube[2]]);
    let want = 7.0 + (1.0 - (5.0 * dist).tanh());
    assert!(
        (e.dense_reward() - want).abs() < 1e-6,
        "{} vs {want}",
        e.dense_reward()
    );

    // Fit needs angle_diff < 0.05 strictly and head_to_cube ≤ 0.025.
    put(&mut e, "cube", cube, rotz(peg_yaw + 0.06));
    assert!(!e.info().flag("is_peg_cube_fit"));
    put(
        &mut e,
        "cube",
        [peg[0] + 0.12 + 0.026, peg[1], 0.02],
        rotz(peg_yaw),
    );
    assert!(!e.info().flag("is_peg_cube_fit"));

    // Stage 4: cube within 5 cm (xy) of the goal while the peg is held and fitted but the
    // arm moves ⇒ no success; the static term 1 − tanh(5·‖qvel[:-2]‖) is added to stage 1–3.
    let placed = [goal[0] - 0.03, goal[1], 0.02];
    put(&mut e, "cube", placed, rotz(0.0));
    let qv = [0.3, 0.0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.5, 0.5];
    set_robot_qvel(&mut e, &qv);
    let info = e.info().clone();
    assert!(info.flag("is_cube_placed") && !info.success(), "{info:?}");
    let d = norm(&part(&e, "extra/tcp_to_peg_pos"));
    let base = if info.flag("is_peg_cube_fit") {
        7.0 + (1.0 - (5.0 * norm(&[0.03, 0.0, 0.019])).tanh())
    } else {
        let (h, a) = (
            info.get("head_to_cube_dist").unwrap(),
            info.get("angle_diff").unwrap(),
        );
        assert!(d < 0.01);
        4.0 + (1.0 - (5.0 * h).tanh()) + (1.0 - (5.0 * a).tanh())
    };
    // The gripper velocities (last two) do not count.
    let stat = 1.0 - (5.0 * norm(&[0.3, 0.1])).tanh();
    assert!((e.dense_reward() - (base + stat)).abs() < 1e-6);

    // Placed and the robot static (|arm qvel| ≤ 0.2) ⇒ success ⇒ 10.
    set_robot_qvel(&mut e, &[0.0, 0.15, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.5]);
    assert!(e.info().success());
    assert_eq!(e.dense_reward(), 10.0);

    // Placed within 5 cm (xy) only.
    put(&mut e, "cube", [goal[0] - 0.0499, goal[1], 0.02], rotz(0.0));
    assert!(e.info().flag("is_cube_placed"));
    put(&mut e, "cube", [goal[0] - 0.0501, goal[1], 0.02], rotz(0.0));
    assert!(!e.info().flag("is_cube_placed") && !e.info().success());
}

#[test]
fn placed_cube_with_a_resting_robot_succeeds_after_a_step() {
    let mut e = env_with(None);
    e.reset(Some(2));
    let (c, c2g) = (
        part(&e, "extra/cube_pose"),
        part(&e, "extra/cube_to_goal_pos"),
    );
    put(
        &mut e,
        "cube",
        [c[0] + c2g[0], c[1] + c2g[1], 0.02],
        rotz(0.1),
    );
    let mut s_last = None;
    for _ in 0..3 {
        let s = e.step(&[0.0; 8]).unwrap();
        s_last = Some((s.info.success(), s.reward, s.terminated));
    }
    assert_eq!(s_last, Some((true, 10.0, true)), "dense 10 on success");
}

#[test]
fn upstream_quirks_goal_pos_is_the_peg_head_is_unrotated_angle_is_unwrapped() {
    let mut e = env_with(None);
    e.reset(Some(0));
    // goal_pos holds the peg position.
    let peg = part(&e, "extra/peg_pose");
    close(
        e.obs_part("extra/goal_pos").unwrap(),
        &peg[..3],
        1e-7,
        "goal_pos",
    );

    // Rotate the peg by 0.5 rad: the head stays at peg.p + (0.12, 0, 0) in world axes.
    let p = [0.0, 0.05, 0.025];
    put(&mut e, "peg", p, rotz(0.5));
    let cube = part(&e, "extra/cube_pose");
    let want = [p[0] + 0.12 - cube[0], p[1] - cube[1], p[2] - cube[2]];
    close(
        e.obs_part("extra/peghead_to_cube_pos").unwrap(),
        &want,
        1e-6,
        "head",
    );
    let h = e.info().get("head_to_cube_dist").unwrap();
    assert!((h - norm(&want[..2])).abs() < 1e-6);

    // Yaws of +170° and −170°: upstream reports 340°, not 20° (no wrapping).
    put(&mut e, "peg", p, rotz(-170f64.to_radians()));
    put(
        &mut e,
        "cube",
        [cube[0], cube[1], 0.02],
        rotz(170f64.to_radians()),
    );
    let a = e.info().get("angle_diff").unwrap();
    assert!((a - 340f64.to_radians()).abs() < 1e-9, "{a}");
    // No 90° cube symmetry either: a cube turned by 90° is 90° off.
    put(&mut e, "peg", p, rotz(0.0));
    put(
        &mut e,
        "cube",
        [cube[0], cube[1], 0.02],
        rotz(90f64.to_radians()),
    );
    let a = e.info().get("angle_diff").unwrap();
    assert!((a - 90f64.to_radians()).abs() < 1e-9, "{a}");
    // tcp_pose is the TCP link pose (panda_hand_tcp).
    let m = e.model().clone();
    let tcp = m.require_id(ObjType::Body, "panda_hand_tcp").unwrap();
    let want: Vec<f64> = e.data().xpos()[3 * tcp..3 * tcp + 3].to_vec();
    close(
        &e.obs_part("extra/tcp_pose").unwrap()[..3],
        &want,
        1e-6,
        "tcp",
    );
}

#[test]
fn export_and_determinism() {
    let mjcf = crate::env::scene_mjcf("PokeCube-v1", "panda").unwrap();
    for name in ["\"cube\"", "\"peg\"", "\"goal_region\"", "\"base_camera\""] {
        assert!(
            mjcf.xml.contains(name),
            "{name} missing from the exported MJCF"
        );
    }
    // Bad robot: the error names it and the valid choices.
    let err = crate::env::scene_mjcf("PokeCube-v1", "so100")
        .unwrap_err()
        .to_string();
    assert!(err.contains("so100") && err.contains("panda"), "{err}");
    // Same seed and actions ⇒ bitwise identical observations.
    let run = || {
        let mut e = env_with(None);
        e.reset(Some(7));
        let mut out = Vec::new();
        for k in 0..10 {
            let a = [0.3 * ((k % 3) as f32 - 1.0); 8];
            out.extend_from_slice(e.step(&a).unwrap().obs);
        }
        out
    };
    assert_eq!(run(), run());
}

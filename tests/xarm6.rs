use mjskill::mujoco::Data;
use mjskill::robots::{self, RobotIds};

#[test]
fn explore() {
    let spec = robots::spec("xarm6_robotiq").unwrap();
    let (model, _desc, ids, _) = robots::table_scene_with(spec, |_| {}).unwrap();
    println!("{:?}", ids.joint_names);
    let mut d = Data::new(model.clone()).unwrap();
    ids.set_qpos(&mut d, spec.table_qpos);
    ids.apply_gravity_compensation(&mut d);
    for (k, &q) in spec.table_qpos.iter().enumerate() {
        ids.set_drive_target(&model, &mut d, k, q, 0.0);
    }
    d.forward();
    let pad = ids.body("right_inner_finger_pad").unwrap();
    let base = ids.body("robotiq_arg2f_base_link").unwrap();
    let tcp = ids.tcp_pose(&d);
    println!("tcp {:?}", tcp);
    let mut q = vec![0.0; 12];
    for t in [0.0, 0.81] {
        ids.set_drive_target(&model, &mut d, 6, t, 0.0);
        ids.set_drive_target(&model, &mut d, 8, t, 0.0);
        for s in 0..500 {
            d.step();
            if s % 25 == 0 {
                ids.qpos(&d, &mut q);
                let b = RobotIds::body_pose(&d, base);
                let p = b.inverse() * RobotIds::body_pose(&d, pad);
                let gap = |l1: &str, a1: [f64; 3], l2: &str, a2: [f64; 3]| {
                    let w1 =
                        RobotIds::body_pose(&d, ids.body(l1).unwrap()) * nalgebra::Point3::from(a1);
                    let w2 =
                        RobotIds::body_pose(&d, ids.body(l2).unwrap()) * nalgebra::Point3::from(a2);
                    (w1 - w2).norm()
                };
                let g: Vec<f64> = mjskill::robots::xarm6_robotiq::LOOP_CLOSURES
                    .iter()
                    .map(|c| gap(c.0, c.1, c.2, c.3))
                    .collect();
                println!(
                    "{s} q {:.4?} pad {:.4?} ncon {} gap {:.6?} f {:.3?}",
                    &q[6..],
                    p.translation.vector,
                    d.ncon(),
                    g,
                    &d.actuator_force()[6..]
                );
            }
        }
        println!("{:?}", d.warnings());
    }
}

#[test]
fn explore_solver() {
    use mjskill::cli::eval;
    let config = mjskill::EnvConfig {
        robot: Some("xarm6_robotiq".into()),
        control_mode: Some("pd_ee_delta_pos".into()),
        ..Default::default()
    };
    let mut env = eval::make_env("PickCube-v1", config, "solver").unwrap();
    let mut policy = mjskill::solvers::make_policy("solver", &env, 0).unwrap();
    let seed: u64 = std::env::var("SEED")
        .map(|s| s.parse().unwrap())
        .unwrap_or(0);
    let quiet = std::env::var("QUIET").is_ok();
    for seed in seed..seed + if quiet { 30 } else { 1 } {
    env.reset(Some(seed));
    policy.reset(&env);
    let cube = env
        .model()
        .require_id(mjskill::mujoco::ObjType::Body, "cube")
        .unwrap();
    let mut a = vec![0.0f32; 4];
    let mut q = vec![0.0; 12];
    for t in 0..50 {
        policy.act(&env, &mut a);
        let s = env.step(&a).unwrap();
        let (_, info) = (s.reward, s.info.clone());
        env.robot().qpos(env.data(), &mut q);
        let tcp = env.robot().tcp_pose(env.data()).0;
        let c = &env.data().xpos()[3 * cube..3 * cube + 3];
        if quiet { if t == 49 || t == 19 || t == 25 { let goal = env.model().require_id(mjskill::mujoco::ObjType::Body, "goal_site").unwrap(); let gp = &env.data().xpos()[3*goal..3*goal+3]; println!("seed {seed} t {t} tcp {:.3?} cube {:.3?} goal {:.3?} g {:.3?} grasp {} succ {}", tcp, c, gp, &q[6..], info.flag("is_grasped"), info.success()); } continue; }
        println!(
            "{t} a {:.2?} tcp {:.3?} cube {:.3?} g {:.3?} grasp {} succ {} {:?}",
            a,
            tcp,
            c,
            &q[6..],
            info.flag("is_grasped"),
            info.success(),
            env.data().warnings()
        );
        let d = env.data();
        let gb = env.model().geom_bodyid();
        for i in 0..d.ncon() {
            let (g1, g2) = d.contact_geoms(i);
            let (b1, b2) = (gb[g1] as usize, gb[g2] as usize);
            if b1 == cube || b2 == cube {
                let o = if b1 == cube { b2 } else { b1 };
                println!(
                    "   contact {} f {:.3?} dist {:.5}",
                    env.model().name(mjskill::mujoco::ObjType::Body, o),
                    d.contact_force(i),
                    d.contact(i).dist
                );
            }
        }
    }
}
}

use mjskill::maniskill::fidelity::env_for;
use mjskill::maniskill::reference::RefFile;
use mjskill::SimConfig;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let f = RefFile::open(std::path::Path::new(&a[1])).unwrap();
    let sf: u32 = a[2].parse().unwrap();
    let seed: u64 = a[3].parse().unwrap();
    let obj = &a[4];
    let (t0, t1): (usize, usize) = (a[5].parse().unwrap(), a[6].parse().unwrap());
    let ep = f.episodes.iter().find(|e| e.seed == seed && e.source == "motion_planning").unwrap();
    let mut env = env_for(&f.env_id, &f.robot, &ep.control_mode, SimConfig { sim_freq: sf }).unwrap();
    env.reset(Some(seed));
    let n = f.joint_names.len();
    for (i, s) in ep.steps.iter().enumerate() {
        let st = env.step(s.action.as_ref().unwrap()).unwrap();
        let g = st.info.values.clone();
        if i + 1 >= t0 && i + 1 <= t1 {
            let mut q = vec![0.0; n];
            env.robot().qpos(env.data(), &mut q);
            let p = env.actor_pose(obj).unwrap();
            let r = s.actors[obj.as_str()];
            println!("t{:3} a_g {:+.2} fingers ms {:.4} {:.4} mj {:.4} {:.4} | {} ms ({:.3},{:.3},{:.3}) mj ({:.3},{:.3},{:.3}) | grasp ms {} mj {:?} | force ms {:.1?} ", i + 1, s.action.as_ref().unwrap()[7], s.robot_qpos[7], s.robot_qpos[8], q[7], q[8], obj, r[0], r[1], r[2], p[0], p[1], p[2], s.flag("is_peg_grasped") || s.flag("is_grasped") || s.flag("is_obj_grasped"), g, s.grasp_contact.finger1);
        }
    }
}

// Scratch: dump one-step errors with context for regression.
use mjskill::maniskill::fidelity::env_for;
use mjskill::maniskill::reference::RefFile;
use mjskill::SimConfig;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let f = RefFile::open(std::path::Path::new(&args[1])).unwrap();
    let sf: u32 = args[2].parse().unwrap();
    let mode = args.get(3).cloned().unwrap_or("pd_joint_delta_pos".into());
    let j: usize = args.get(4).map(|s| s.parse().unwrap()).unwrap_or(0);
    let n = f.joint_names.len();
    println!("e v0 v1ms v1mj a q0 ncon");
    for ep in f.episodes.iter().filter(|e| e.control_mode == mode) {
        let mut env = env_for(&f.env_id, &f.robot, &ep.control_mode, SimConfig { sim_freq: sf }).unwrap();
        env.reset(Some(ep.seed));
        let mut prev = &ep.initial;
        for s in &ep.steps {
            env.set_state_dict(&prev.state_dict).unwrap();
            env.step(s.action.as_ref().unwrap()).unwrap();
            let mut q = vec![0.0; n];
            env.robot().qpos(env.data(), &mut q);
            let mut v = vec![0.0; n];
            env.robot().qvel(env.data(), &mut v);
            let robot_bodies = &env.robot().bodies;
            let gb = env.model().geom_bodyid();
            let mut nc = 0;
            for i in 0..env.data().ncon() {
                let (g1, g2) = env.data().contact_geoms(i);
                if robot_bodies.contains(&(gb[g1] as usize)) || robot_bodies.contains(&(gb[g2] as usize)) { nc += 1; }
            }
            println!("{} {} {} {} {} {} {}", q[j] - s.robot_qpos[j], prev.robot_qvel[j], s.robot_qvel[j], v[j], s.action.as_ref().unwrap()[j.min(s.action.as_ref().unwrap().len()-1)], prev.robot_qpos[j], nc);
            prev = s;
        }
    }
}

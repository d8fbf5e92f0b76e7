// Scratch analysis (not committed): per-joint one-step errors against a ManiSkill file.
use mjskill::maniskill::fidelity::env_for;
use mjskill::maniskill::reference::RefFile;
use mjskill::SimConfig;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let f = RefFile::open(std::path::Path::new(&args[1])).unwrap();
    let sf: u32 = args[2].parse().unwrap();
    let mode = args.get(3).cloned().unwrap_or("pd_joint_delta_pos".into());
    let n = f.joint_names.len();
    let mut sum = vec![0.0f64; n];
    let mut sumsq = vec![0.0f64; n];
    let mut signed = vec![0.0f64; n];
    let mut cnt = 0.0;
    for ep in f.episodes.iter().filter(|e| e.control_mode == mode) {
        let mut env = env_for(&f.env_id, &f.robot, &ep.control_mode, SimConfig { sim_freq: sf }).unwrap();
        env.reset(Some(ep.seed));
        let mut prev = &ep.initial;
        for s in &ep.steps {
            env.set_state_dict(&prev.state_dict).unwrap();
            env.step(s.action.as_ref().unwrap()).unwrap();
            let mut q = vec![0.0; n];
            env.robot().qpos(env.data(), &mut q);
            for j in 0..n {
                let e = q[j] - s.robot_qpos[j];
                sum[j] += e.abs();
                sumsq[j] += e * e;
                // signed relative to the ManiSkill displacement direction
                let d = s.robot_qpos[j] - prev.robot_qpos[j];
                signed[j] += e * d.signum();
            }
            cnt += 1.0;
            prev = s;
        }
    }
    for j in 0..n {
        println!("{:28} mean|e| {:.2e}  rms {:.2e}  overshoot(+)/lag(-) {:+.2e}", f.joint_names[j], sum[j] / cnt, (sumsq[j] / cnt).sqrt(), signed[j] / cnt);
    }
}

use mjskill::*;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let (id, robot, n): (&str, &str, u64) = (&a[1], &a[2], a[3].parse().unwrap());
    let verbose: Option<u64> = a.get(4).map(|s| s.parse().unwrap());
    let mode = solvers::required_control_mode("solver", robot);
    let mut env = make(id, EnvConfig { robot: Some(robot.into()), control_mode: mode.map(|m| m.to_string()), sim: SimConfig { sim_freq: std::env::var("SF").map(|s| s.parse().unwrap()).unwrap_or(100) }, ..Default::default() }).unwrap();
    let mut pol = solvers::make_policy("solver", &env, 0).unwrap();
    let mut act = vec![0.0f32; env.action_space().shape[0]];
    let mut fails = vec![];
    for seed in 0..n {
        if verbose.is_some() && verbose != Some(seed) { continue; }
        env.reset(Some(seed));
        pol.reset(&env);
        let mut ok = false;
        for t in 0..50 {
            pol.act(&env, &mut act);
            let (term, rew) = { let s = env.step(&act).unwrap(); (s.terminated, s.reward) };
            ok |= term;
            if verbose.is_some() {
                let info = env.info();
                let keys: Vec<String> = info.keys.iter().zip(&info.values).map(|(k, v)| format!("{}={:.3}", &k[..k.len().min(10)], v)).collect();
                let q: Vec<String> = env.obs()[7..9].iter().map(|x| format!("{:.4}", x)).collect();
                println!("t{:2} r={:.2} {} q={:?}", t + 1, rew, keys.join(" "), q);
            }
        }
        if !ok { fails.push(seed); }
    }
    println!("fails {:?}", fails);
}

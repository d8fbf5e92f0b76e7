use mjskill::{make, EnvConfig};
use mjskill::solvers::make_policy;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let task = &a[1];
    let seeds: Vec<u64> = a[2].split(',').map(|x| x.parse().unwrap()).collect();
    let verbose = a.len() > 3;
    let mut env = make(task, EnvConfig { robot: Some("fetch".into()), control_mode: Some("pd_ee_delta_pose".into()), ..Default::default() }).unwrap();
    let gl = env.robot().body("gripper_link").unwrap();
    let names = ["sphere","bin","peg","cube","goal_region"];
    let ids: Vec<(usize,&str)> = names.iter().filter_map(|n| mjskill::tasks::body_id(env.model(), n).ok().map(|i|(i,*n))).collect();
    let mut pol = make_policy("solver", &env, 0).unwrap();
    let n = env.action_space().shape[0];
    let mut act = vec![0f32; n];
    for s in seeds {
        env.reset(Some(s));
        pol.reset(&env);
        let mut first = None;
        for t in 0..50 {
            pol.act(&env, &mut act);
            let x = env.data().xpos();
            if verbose {
                let sh = env.robot().body("shoulder_lift_link").unwrap(); let mut line = format!("sh=({:.3},{:.3}) t{t} g=", x[3*sh], x[3*sh+2]); line += &format!("({:.3},{:.3},{:.3})", x[3*gl], x[3*gl+1], x[3*gl+2]);
                for (i,nm) in &ids { line += &format!(" {nm}=({:.3},{:.3},{:.3})", x[3*i], x[3*i+1], x[3*i+2]); }
                line += &format!(" a={:?}", act.iter().map(|v| (v*100.0).round()/100.0).collect::<Vec<_>>());
                println!("{line}");
            }
            let st = env.step(&act).unwrap();
            if st.info.success() && first.is_none() { first = Some(t); }
            if verbose && t == 49 { println!("{:?}", st.info); }
        }
        let x = env.data().xpos();
        let mut line = format!("seed {s} first {first:?}");
        for (i,nm) in &ids { line += &format!(" {nm}=({:.3},{:.3},{:.3})", x[3*i], x[3*i+1], x[3*i+2]); }
        println!("{line}");
    }
}

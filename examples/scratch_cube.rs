use mjskill::*;
fn main() {
    let sf: u32 = std::env::args().nth(1).unwrap().parse().unwrap();
    let mut env = make("PickCube-v1", EnvConfig { sim: SimConfig { sim_freq: sf }, ..Default::default() }).unwrap();
    env.reset(Some(1000));
    println!("init {:?}", env.actor_pose("cube").unwrap());
    let a = vec![0.0f32; 8];
    for t in 0..5 {
        env.step(&a).unwrap();
        let sd = env.get_state_dict();
        println!("t{} {:?}", t + 1, &sd.actors["cube"]);
    }
}

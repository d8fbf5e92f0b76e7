use mjskill::*;
fn main() {
    let sf: u32 = std::env::args().nth(1).unwrap().parse().unwrap();
    let mut env = make("PickCube-v1", EnvConfig { sim: SimConfig { sim_freq: sf }, ..Default::default() }).unwrap();
    env.reset(Some(1000));
    let mut d = env.data().clone();
    let cube = env.model().id(mujoco::ObjType::Body, "cube").unwrap();
    for i in 0..8 {
        d.step1();
        let nc = d.ncon();
        let mut dists = vec![];
        for c in 0..nc { let (g1,g2)=d.contact_geoms(c); let gb=env.model().geom_bodyid(); if gb[g1] as usize==cube || gb[g2] as usize==cube { dists.push(d.contact(c).dist); } }
        d.step2();
        println!("sub {} z {:.9} ncon_cube {} dists {:?} qacc_z {:.4}", i+1, d.xpos()[3*cube+2], dists.len(), dists, d.qacc()[9+2]);
    }
}

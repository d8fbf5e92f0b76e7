//! Robot links that can never reach the table top or the floor (`RobotSpec::clear_of_world`)
//! have their contacts with the world's geoms excluded (docs/speed.md, "Cuts"). These tests
//! check the lists against the robots' joint ranges.
use rand::{Rng, SeedableRng};

use crate::mujoco::{Data, ObjType};

/// Least distance (m) between a link listed in `RobotSpec::clear_of_world` and the table top
/// or the floor over the joint ranges.
const CLEARANCE: f64 = 0.02;

/// The lowest point (m) each robot body's colliding geoms reach over `samples` joint
/// configurations drawn uniformly within the joint ranges (a superset of what the robot can
/// reach: self-collision and the table are ignored), taking each geom as its bounding sphere.
fn lowest_points(robot: &str, samples: usize) -> Vec<(String, f64)> {
    let spec = crate::robots::spec(robot).unwrap();
    let scene = crate::robots::table_scene_with(spec, |_| {}).unwrap();
    let m = scene.model.clone();
    let mut d = Data::new(m.clone()).unwrap();
    let mut low = vec![f64::INFINITY; m.nbody()];
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    for _ in 0..samples {
        for j in 0..m.njnt() {
            let a = m.jnt_qposadr()[j] as usize;
            let (lo, hi) = if m.jnt_limited()[j] != 0 {
                (m.jnt_range()[2 * j], m.jnt_range()[2 * j + 1])
            } else {
                (-std::f64::consts::PI, std::f64::consts::PI)
            };
            d.qpos_mut()[a] = rng.random_range(lo..=hi);
        }
        d.update_kinematics();
        for g in 0..m.ngeom() {
            if m.geom_contype()[g] == 0 && m.geom_conaffinity()[g] == 0 {
                continue;
            }
            let b = m.geom_bodyid()[g] as usize;
            let z = d.geom_xpos()[3 * g + 2] - m.geom_rbound()[g];
            low[b] = low[b].min(z);
        }
    }
    (1..m.nbody())
        .filter(|&b| low[b].is_finite())
        .map(|b| (m.name(ObjType::Body, b), low[b]))
        .collect()
}

#[test]
fn links_excluded_from_the_world_never_come_near_the_table_or_the_floor() {
    for robot in ["panda", "fetch", "xarm6_robotiq", "so100", "widowxai"] {
        let spec = crate::robots::spec(robot).unwrap();
        let low = lowest_points(robot, 20_000);
        for link in spec.clear_of_world {
            let (_, z) = low
                .iter()
                .find(|(n, _)| n == link)
                .unwrap_or_else(|| panic!("{robot}: no link {link}"));
            assert!(
                *z > CLEARANCE,
                "{robot}: {link} comes down to z = {z:.3} m; it is not clear of the world"
            );
        }
        // The list is not empty for want of trying: the robots on the table have such links.
        if robot != "fetch" && robot != "widowxai" {
            assert!(!spec.clear_of_world.is_empty(), "{robot}");
        }
    }
}

#[test]
fn the_clear_links_have_no_contact_with_the_world_in_the_scene() {
    // The exclusions are in the physics model: MuJoCo's `<exclude body1="world">`.
    for robot in ["panda", "xarm6_robotiq", "so100"] {
        let spec = crate::robots::spec(robot).unwrap();
        let scene = crate::robots::table_scene_with(spec, |_| {}).unwrap();
        for link in spec.clear_of_world {
            assert!(
                scene
                    .mjcf
                    .xml
                    .contains(&format!("<exclude body1=\"world\" body2=\"{link}\"/>")),
                "{robot}: {link}"
            );
        }
    }
}

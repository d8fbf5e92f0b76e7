//! PushT-v1's pseudo render against ManiSkill's: `world_to_goal_trans` and the intersection of
//! 400 T poses recorded by `tests/data/maniskill_initial/record.py` (the PushT file's
//! `pseudo_render`), computed by [`PseudoRender`] from the same float32 poses.

use serde::Deserialize;

use crate::tasks::push_t::{PseudoRender, INTERSECTION_THRESH};

#[derive(Deserialize)]
struct File {
    pseudo_render: Render,
}

#[derive(Deserialize)]
struct Render {
    world_to_goal: Vec<f32>,
    samples: Vec<Sample>,
}

#[derive(Deserialize)]
struct Sample {
    pose: [f32; 7],
    intersection: f64,
}

fn recorded() -> Render {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/maniskill_initial/PushT-v1__panda_stick.json");
    let f: File = serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap();
    f.pseudo_render
}

#[test]
fn the_pseudo_render_equals_maniskills_on_recorded_poses() {
    let rec = recorded();
    let r = PseudoRender::new();
    let w = r.world_to_goal();
    for (k, want) in rec.world_to_goal.iter().enumerate() {
        let got = w[k / 3][k % 3];
        assert!(
            (got - want).abs() <= 2e-7,
            "world_to_goal[{k}]: {got} vs {want}"
        );
    }
    assert_eq!(rec.samples.len(), 400);
    let pixel = 1.0 / r.area() as f64;
    let (mut exact, mut worst, mut successes) = (0, 0.0f64, 0);
    for s in &rec.samples {
        let [px, py, _, qw, qx, qy, qz] = s.pose;
        let got = r.intersection(px, py, [qw, qx, qy, qz]);
        let d = (got - s.intersection).abs();
        // ManiSkill's value is hits/825 in float32, recorded to float32's shortest decimal.
        exact += (d < 1e-6) as usize;
        worst = worst.max(d);
        successes += (s.intersection >= INTERSECTION_THRESH) as usize;
        let agree = (got >= INTERSECTION_THRESH) == (s.intersection >= INTERSECTION_THRESH);
        assert!(
            agree || (got - INTERSECTION_THRESH).abs() <= 2.0 * pixel,
            "{:?}: {got} vs {}",
            s.pose,
            s.intersection
        );
    }
    eprintln!("pseudo render: {exact}/400 exact, worst {worst:.2e}, {successes} successes");
    // The poses cover successes and failures; at most a pixel or two differs anywhere.
    assert!((20..=380).contains(&successes), "{successes}");
    assert!(exact >= 396, "{exact} of 400 exact");
    assert!(worst <= 2.0 * pixel + 1e-9, "{worst}");
}

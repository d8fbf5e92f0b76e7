//! PegInsertionSide-v1's per-episode shapes: the physics model that a reset edits in place
//! equals, byte for byte, the model compiled afresh from the scene with the episode's shapes,
//! over resets that grow and shrink every shape, and a state saved in one episode restores its
//! shapes in another.

use crate::env::{make, EnvConfig};

fn env() -> crate::env::Env {
    make("PegInsertionSide-v1", EnvConfig::default()).unwrap()
}

#[test]
fn the_model_edited_at_each_reset_equals_the_model_compiled_with_its_shapes() {
    let mut e = env();
    let mut sizes = Vec::new();
    for seed in [0, 1, 2, 1000, 7, 0] {
        e.reset(Some(seed));
        let fresh = e.compile_physics_model().unwrap();
        assert!(
            e.model().to_mjb() == fresh.to_mjb(),
            "seed {seed}: the edited model differs from the compiled one"
        );
        sizes.push(e.model().geom_size().to_vec());
    }
    // The shapes did change between episodes, and come back with the seed.
    assert_ne!(sizes[0], sizes[1]);
    assert_eq!(sizes[0], sizes[5]);
    // Unseeded resets draw new shapes from the main RNG.
    e.reset(None);
    assert_ne!(e.model().geom_size(), &sizes[5][..]);
    let fresh = e.compile_physics_model().unwrap();
    assert!(e.model().to_mjb() == fresh.to_mjb(), "unseeded reset");
}

#[test]
fn a_saved_state_brings_its_shapes_and_its_future() {
    let mut e = env();
    e.reset(Some(3));
    let action = vec![0.05f32; e.action_space().shape[0]];
    e.step(&action).unwrap();
    let saved = e.get_state();
    let mut want = Vec::new();
    for _ in 0..5 {
        want.push(e.step(&action).unwrap().obs.to_vec());
    }
    e.reset(Some(4));
    assert_ne!(e.get_state().geometry, saved.geometry);
    e.set_state(&saved).unwrap();
    assert!(e.model().to_mjb() == e.compile_physics_model().unwrap().to_mjb());
    for (k, w) in want.iter().enumerate() {
        assert_eq!(&e.step(&action).unwrap().obs.to_vec(), w, "step {k}");
    }
    // Shapes out of range are refused, naming the value; the env is left as it was.
    let mut bad = saved.clone();
    bad.geometry[1] = 0.5;
    let err = e.set_state(&bad).unwrap_err().to_string();
    assert!(err.contains("radius 0.5"), "{err}");
    bad.geometry.pop();
    let err = e.set_state(&bad).unwrap_err().to_string();
    assert!(err.contains("4 values"), "{err}");
}

#[test]
fn an_episode_is_the_same_after_any_earlier_episodes() {
    let action: Vec<f32> = (0..8).map(|k| 0.3 * ((k as f32) * 0.7).sin()).collect();
    let run = |earlier: &[u64]| {
        let mut e = env();
        for &s in earlier {
            e.reset(Some(s));
            e.step(&action).unwrap();
        }
        e.reset(Some(11));
        let mut out = e.obs().to_vec();
        for _ in 0..20 {
            out.extend_from_slice(e.step(&action).unwrap().obs);
        }
        out
    };
    let fresh = run(&[]);
    assert_eq!(run(&[3, 1000]), fresh);
    assert_eq!(run(&[11, 11]), fresh);
}

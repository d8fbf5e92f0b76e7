//! The physics model leaves out the geoms that only draw (docs/speed.md, "Cuts"): the env
//! steps a model without the visual meshes and markers, and the renderer draws a second
//! model with them. These tests hold that cut to its promise: nothing in the physics model
//! only draws, the render model has the same bodies, joints and cameras, and stepping the
//! full model gives the same trajectory, bit for bit.

use mjskill::mujoco::{Data, ObjType};
use mjskill::{make, registry, Env, EnvConfig};
use rand::{Rng, SeedableRng};

/// Every (env id, robot) pair of the registry.
fn pairs() -> Vec<(&'static str, &'static str)> {
    registry()
        .into_iter()
        .flat_map(|e| e.robots.into_iter().map(move |(r, _)| (e.id, r)))
        .collect()
}

/// The env of a pair, state observations.
fn env(id: &str, robot: &str) -> Env {
    make(
        id,
        EnvConfig {
            robot: Some(robot.into()),
            ..Default::default()
        },
    )
    .unwrap()
}

#[test]
fn the_physics_model_has_no_drawn_only_geom_and_the_render_model_has_them_all() {
    for (id, robot) in pairs() {
        let mut e = env(id, robot);
        assert!(e.render_model().is_none(), "{id}/{robot}: no renderer yet");
        e.render()
            .expect("rendering must be available (bash .ci/setup installs EGL/Mesa)");
        let (m, full) = (e.model().clone(), e.render_model().unwrap().clone());
        for g in 0..m.ngeom() {
            assert!(
                m.geom_contype()[g] != 0 || m.geom_conaffinity()[g] != 0,
                "{id}/{robot}: physics geom {:?} only draws",
                m.name(ObjType::Geom, g)
            );
        }
        let drawn_only = (0..full.ngeom())
            .filter(|&g| full.geom_contype()[g] == 0 && full.geom_conaffinity()[g] == 0)
            .count();
        assert!(
            drawn_only > 0,
            "{id}/{robot}: the render model lost its visuals"
        );
        assert_eq!(full.ngeom(), m.ngeom() + drawn_only, "{id}/{robot}");
        assert_eq!(
            (
                full.nbody(),
                full.nq(),
                full.nv(),
                full.nmocap(),
                full.ncam()
            ),
            (m.nbody(), m.nq(), m.nv(), m.nmocap(), m.ncam()),
            "{id}/{robot}"
        );
        // Every colliding geom of the render model is in the physics model, by name.
        for g in 0..full.ngeom() {
            if full.geom_contype()[g] != 0 || full.geom_conaffinity()[g] != 0 {
                let name = full.name(ObjType::Geom, g);
                assert!(
                    m.require_id(ObjType::Geom, &name).is_ok(),
                    "{id}/{robot}: {name} missing from the physics model"
                );
            }
        }
        assert_eq!(
            e.geom_segmentation_ids().len(),
            full.ngeom(),
            "{id}/{robot}: labels follow the render model once there is one"
        );
    }
}

#[test]
fn the_full_model_steps_the_same_trajectory_bit_for_bit() {
    for (id, robot) in pairs() {
        let mut e = env(id, robot);
        e.render().unwrap();
        e.reset(Some(7));
        // After the reset: PegInsertionSide-v1's shapes change with the episode, and the
        // renderer is rebuilt for them.
        let full = e.render_model().unwrap().clone();
        // The same state on the full model.
        let mut state = Vec::new();
        e.data().get_state(&mut state);
        let mut data = Data::new(full).unwrap();
        data.set_state(&state).unwrap();
        let mut drives = e.drives().clone();
        let dim = e.action_space().shape[0];
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut targets = Vec::new();
        for _ in 0..60 {
            let a: Vec<f32> = (0..dim).map(|_| rng.random_range(-1.0..1.0)).collect();
            e.step(&a).unwrap();
            targets.clear();
            e.drives().save_targets(&mut targets);
            drives.load_targets(&targets);
            for _ in 0..e.substeps() {
                drives.step(&mut data);
            }
            data.update_kinematics();
            assert_eq!(data.qpos(), e.data().qpos(), "{id}/{robot}");
            assert_eq!(data.qvel(), e.data().qvel(), "{id}/{robot}");
        }
    }
}

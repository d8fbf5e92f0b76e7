//! Scripted solvers and `eval`.

use mjskill::cli::eval;
use mjskill::EnvConfig;

#[test]
fn pickcube_panda_solver_succeeds_on_seeds_0_to_19() {
    let r = eval::run("PickCube-v1", EnvConfig::default(), "solver", 20, 0).unwrap();
    assert_eq!(r.control_mode, "pd_ee_delta_pos");
    assert!(r.successes >= 19, "{r:?}");
    // The cube is held at the goal until the end, and the dense reward accumulates.
    assert!(r.success_at_end_rate >= 0.95, "{r:?}");
    assert!(r.mean_return > 25.0, "{r:?}");
    let first = r.mean_first_success_step.unwrap();
    assert!((12.0..35.0).contains(&first), "{first}");
}

#[test]
fn zero_and_random_policies_do_not_solve_pickcube() {
    let r = eval::run("PickCube-v1", EnvConfig::default(), "zero", 3, 0).unwrap();
    assert_eq!(r.successes, 0);
    let r = eval::run("PickCube-v1", EnvConfig::default(), "random", 3, 0).unwrap();
    assert_eq!(r.successes, 0);
    assert!(r.mean_return.is_finite());
}

#[test]
fn policy_errors_name_the_problem() {
    let e = eval::run("PickCube-v1", EnvConfig::default(), "telepathy", 1, 0).unwrap_err();
    assert!(
        e.contains("telepathy") && e.contains("solver, random, zero"),
        "{e}"
    );
    let config = EnvConfig {
        control_mode: Some("pd_joint_pos".into()),
        ..Default::default()
    };
    let e = eval::run("PickCube-v1", config, "solver", 1, 0).unwrap_err();
    assert!(
        e.contains("pd_ee_delta_pos") && e.contains("pd_joint_pos"),
        "{e}"
    );
}

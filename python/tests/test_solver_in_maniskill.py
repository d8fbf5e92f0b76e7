"""examples/solver_in_maniskill.py's mjskill side, without ManiSkill: the step-by-step summary
(`OneStep`), the task flags it reads, and the solver's own closed loop in mjskill with a pinch
solver."""

import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "examples"))
import solver_in_maniskill as sim  # noqa: E402


def test_one_step_summary_counts_held_steps_and_their_static_verdicts():
    s = sim.OneStep()
    # (error, held, ManiSkill static, mjskill static)
    s.add(0.001, False, False, False)
    s.add(0.004, True, True, True)
    s.add(0.002, True, True, False)
    s.add(0.010, True, False, False)
    s.add(0.030, True, None, True)  # a task without the flag on one side: not judged
    out = s.summary()
    assert out["steps"] == 5
    assert out["arm_error_median"] == pytest.approx(0.004)
    assert out["held_steps"] == 4
    assert out["arm_error_held_median"] == pytest.approx((0.004 + 0.010) / 2)
    assert out["held_static_judged"] == 3
    assert out["held_static_maniskill"] == 2
    assert out["held_static_mjskill"] == 1
    assert out["held_static_same"] == 2


def test_one_step_summary_of_no_held_steps_has_no_medians_to_give():
    s = sim.OneStep()
    s.add(0.002, False, None, None)
    out = s.summary()
    assert out["held_steps"] == 0 and out["arm_error_held_median"] is None
    assert out["held_static_judged"] == 0 and out["held_static_same"] == 0
    assert sim.OneStep().summary()["arm_error_median"] is None


def test_flags_read_from_either_simulators_info_or_none_where_the_task_has_none():
    assert sim.flag({"is_grasped": np.array([True])}, "is_grasped") is True
    assert sim.flag({"is_grasped": False}, "is_grasped") is False
    assert sim.flag({"success": True}, "is_robot_static") is None


def test_the_solvers_own_closed_loop_in_mjskill_with_either_pinch_solver():
    ends = {}
    for pinch_solver in ["mujoco", "physx_tgs"]:
        env = sim.make_mjskill("PickCubeSO100-v1", "so100", "pd_joint_pos", pinch_solver)
        results = [sim.mjskill_closed_loop(env, seed) for seed in range(5000, 5003)]
        assert all(any_ or not last for last, any_ in results)  # success at the end is success
        assert sum(any_ for _, any_ in results) >= 2
        ends[pinch_solver] = sim.arm_qpos_mjskill(env, 5)
        # The arm joints are the state dict's.
        art = np.asarray(env.unwrapped.get_state_dict()["articulations"]["so100"])
        np.testing.assert_array_equal(ends[pinch_solver], art[13:18])
        env.close()
    # The pinch solver reaches the env: the held arm ends elsewhere.
    assert np.abs(ends["mujoco"] - ends["physx_tgs"]).max() > 1e-4

"""examples/compare_in_maniskill.py's attribution of an action difference to the policy's
readings (`open_action_gap`), without ManiSkill: the observation's readings, named per
joint, and which of them moves a policy's action, on policies whose answer is known."""

import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "examples"))
import compare_in_maniskill as cmp  # noqa: E402

LAYOUT = [("agent/qpos", 0, 2), ("agent/qvel", 2, 4), ("extra/tcp_pose", 4, 11)]


def linear(w):
    w = np.asarray(w, np.float64)
    return lambda o: w @ np.asarray(o, np.float64)


def test_joint_readings_are_named_by_joint_and_the_rest_by_entry():
    g = cmp.reading_groups(LAYOUT, ["head_tilt_joint", "elbow_flex_joint"])
    assert g == {"agent/qpos/head_tilt_joint": [0], "agent/qpos/elbow_flex_joint": [1],
                 "agent/qvel/head_tilt_joint": [2], "agent/qvel/elbow_flex_joint": [3],
                 "extra/tcp_pose": list(range(4, 11))}
    # Names that do not match the entry's size leave it whole.
    assert cmp.reading_groups(LAYOUT, ["only_one"])["agent/qpos"] == [0, 1]


def test_the_reading_that_moves_the_action_most_comes_first():
    groups = cmp.reading_groups(LAYOUT, ["head", "elbow"])
    # The action reads the head's position 50 times as strongly as the elbow's.
    w = np.zeros((2, 11))
    w[0, 0], w[1, 1], w[1, 4] = 50.0, 1.0, 3.0
    ref = np.zeros(11)
    other = ref.copy()
    other[0], other[1], other[4] = 0.002, 0.002, 0.001
    gap, moves = cmp.action_readings(linear(w), ref, other, groups)
    assert np.isclose(gap, 0.1), gap
    assert moves[0][0] == "agent/qpos/head" and np.isclose(moves[0][1], 0.1), moves
    assert moves[1][0] == "extra/tcp_pose" and np.isclose(moves[1][1], 0.003), moves
    assert moves[2][0] == "agent/qpos/elbow" and np.isclose(moves[2][1], 0.002), moves
    # Readings that differ in nothing move nothing.
    assert dict(moves)["agent/qvel/head"] == 0.0


def test_the_largest_gap_is_looked_for_only_before_the_states_part():
    groups = cmp.reading_groups(LAYOUT, ["head", "elbow"])
    policy = linear(np.eye(11)[:2])
    ms = [np.zeros(11) for _ in range(4)]
    mj = [np.zeros(11) for _ in range(4)]
    mj[1][1] = 0.01  # the elbow, after one step
    mj[3][0] = 0.5  # the head, after three steps (the states have parted by then)
    best = cmp.largest_action_gap(policy, ms, mj, groups, until=3)
    assert best["step"] == 1 and np.isclose(best["gap"], 0.01), best
    assert best["readings"][0] == ["agent/qpos/elbow", 0.01], best
    assert len(best["readings"]) == cmp.TOP_READINGS
    best = cmp.largest_action_gap(policy, ms, mj, groups, until=None)
    assert best["step"] == 3 and best["readings"][0][0] == "agent/qpos/head", best


class _ManiSkill:
    """ManiSkill's side: records what it is set to; stepped from the state of t = 1 (before
    mjskill's second step), its robot is static and the task succeeds; from the others not."""

    def __init__(self):
        self.unwrapped = self
        self.agent = self
        self.robot = self
        self.log = []

    def reset(self, seed):
        self.log.append(("reset", seed))

    def set_state_dict(self, d):
        self.t = int(d["actors"]["cube"][0, 0])
        self.log.append(("state", self.t))

    def set_controller_state(self, c):
        self.log.append(("controller", float(c["target_qpos"][0, 0])))

    def get_active_joints(self):
        return ["j0", "j1"]

    def set_joint_drive_targets(self, q, joints):
        self.log.append(("drive", float(q[0, 0]), tuple(joints)))

    def set_joint_drive_velocity_targets(self, v, joints):
        pass

    def step(self, action):
        self.log.append(("step", float(np.asarray(action).reshape(-1)[0])))
        info = {"is_robot_static": np.array([self.t == 1]),
                "success": np.array([self.t == 1])}
        return None, 0.0, False, False, info


def _state(t):
    """A state dict of mjskill's layout whose every entry tells the step t it was taken at."""
    return {"actors": {"cube": np.full(13, t, np.float32)},
            "articulations": {"robot": np.full(3, t, np.float32)},
            "controller": {"target_qpos": np.full(2, t, np.float32)},
            "drive": {"target_qpos": np.full(2, 10 + t, np.float32),
                      "target_qvel": np.zeros(2, np.float32)}}


def test_physx_steps_take_each_of_mjskill_s_steps_from_its_state():
    ms = _ManiSkill()
    record = [(_state(t), np.array([t + 0.5], np.float32)) for t in range(3)]
    # mjskill's robot is static after its second and third steps.
    snaps = [cmp.Snapshot(np.zeros(2), None, None, {"is_robot_static": t >= 1})
             for t in range(3)]
    last, any_, differ = cmp.physx_steps(ms, 7, record, snaps, np.asarray)
    # Each step: a fresh reset, mjskill's state before the step (t = 0, 1, 2), its controller
    # and drive targets, then the action mjskill took.
    assert ms.log == [
        ("reset", 7), ("state", 0), ("controller", 0.0), ("drive", 10.0, ("j0", "j1")),
        ("step", 0.5),
        ("reset", 7), ("state", 1), ("controller", 1.0), ("drive", 11.0, ("j0", "j1")),
        ("step", 1.5),
        ("reset", 7), ("state", 2), ("controller", 2.0), ("drive", 12.0, ("j0", "j1")),
        ("step", 2.5),
    ], ms.log
    # ManiSkill's success from those states: not at the last step, but at one before it.
    assert (last, any_) == (False, True)
    # Static: mjskill F, T, T; ManiSkill F, T, F: they differ at the last step only.
    assert differ == 1


def test_held_steps_keep_a_few_spread_held_steps_as_json_ready_cases():
    held = [False, True, True, True, True, False, True]
    states = [{"actors": {"cube": np.arange(3.0) + t}, "drive": {"target_qpos": np.ones(2) * t}}
              for t in range(len(held))]
    actions = [np.full(2, t, np.float32) for t in range(len(held))]
    snaps = [cmp.Snapshot(np.full(2, t), None, None, {"is_robot_static": t % 2 == 0},
                          qvel=np.full(2, -t)) for t in range(len(held))]
    cases = cmp.held_steps(7, states, actions, snaps, held, 3)
    # The first, middle and last of the five held steps (1, 2, 3, 4, 6).
    assert [c["step"] for c in cases] == [1, 3, 6]
    c = cases[1]
    assert c["seed"] == 7 and c["action"] == [3.0, 3.0]
    assert c["state_dict"]["actors"]["cube"] == [3.0, 4.0, 5.0]
    assert c["state_dict"]["drive"]["target_qpos"] == [3.0, 3.0]
    assert c["qpos"] == [3.0, 3.0] and c["qvel"] == [-3.0, -3.0]
    assert c["is_robot_static"] is False
    # Fewer held steps than asked: all of them.
    every = cmp.held_steps(7, states, actions, snaps, held, 9)
    assert [c["step"] for c in every] == [1, 2, 3, 4, 6]
    json.dumps(cases)


def test_every_tasks_grasp_flag_counts_as_held():
    assert cmp.grasped({"is_grasped": True})
    assert cmp.grasped({"is_obj_grasped": True, "success": False})
    assert cmp.grasped({"is_peg_grasped": True})
    assert not cmp.grasped({"is_peg_grasped": False, "success": True})
    assert not cmp.grasped({})
    assert set(cmp.GRASP_FLAGS) <= set(cmp.FLAGS)

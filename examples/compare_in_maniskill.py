"""Runs one policy file in ManiSkill 3 and in mjskill on the same seeds and reports, per
episode, where the two simulators part: the first step and the quantity (arm joints, gripper,
TCP, object, a task flag) whose difference passes its tolerance.

    pip install mani_skill onnxruntime             # where ManiSkill runs, plus mjskill's wheel
    python examples/compare_in_maniskill.py policy.onnx --episodes 10 --seed 10000

ManiSkill runs the policy closed loop on its own observations. mjskill then takes the same
seed three ways, or four:

* closed: the policy closed loop on mjskill's observations, as `mjskill eval` runs it; its
  success and the first step where its state parts from ManiSkill's. This is what a user
  who moves a policy between the two simulators sees.
* open: ManiSkill's actions replayed open loop; the first parting step with no policy
  feedback, so the physics alone.
* resync: before every step mjskill takes ManiSkill's state (poses, velocities, the drive
  targets PhysX holds) and the same action; the largest arm-joint error after that one step,
  split by whether ManiSkill holds the object. This is the one-step error of the dynamics.
  On the steps where it holds nothing, the largest error and the number of steps above 5 mrad
  (`one_step_free_steps_over_5mrad`) show contacts the two simulators make differently before
  a grasp (a jaw grazing the object as it descends, docs/outcome-physics.md).
* physx steps (`--physx-steps`, the other way round): each step of mjskill's closed loop is
  also taken by PhysX: a freshly reset ManiSkill env gets mjskill's state before the step
  (poses, velocities, controller and drive targets) and the same action.
  `physx_step_success` is ManiSkill's success on those steps, `static_differs` the number of
  steps where ManiSkill's `is_robot_static` is not mjskill's. It tells how much of a gap the
  velocities PhysX reports from a state account for: they fail `is_robot_static` on a still,
  pinching SO100 (docs/outcome-physics.md).

With the open loop it also finds which of the policy's readings turn small state differences
into different actions: at each step before the open-loop states part, the policy acts on
ManiSkill's observation and on mjskill's, and then on ManiSkill's with one reading at a time
(a joint's position or velocity, named by ManiSkill's joint names, or another entry of the
state observation) taken from mjskill's. The step with the largest action difference and the
readings that move the action most there are reported (`open_action_gap`). A reading the
task does not need (the Fetch's head, docs/training.md) shows up there, and
`examples/imitate.py --hide-obs` hides it.

Its successes are success at the last step (`success_at_end` of eval_in_maniskill.py, whose
headline figure is success at any step, as `mjskill eval`'s is).

Prints one JSON line per episode and a summary line (`"summary": true`): successes in both,
agreement of the final outcome, the median first parting step and its most common quantity,
and the median one-step arm error (first step from the seeded state, and over all steps).
`--json FILE` also writes every line to FILE. Needs numpy, onnxruntime, mani_skill and the
mjskill Python package in one environment.
"""

import argparse
import collections
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from eval_in_maniskill import FIXED_ROBOT, act, load, to_numpy  # noqa: E402

#: Tolerances of "the states have parted", per quantity: joint positions in rad (or m for
#: prismatic joints), positions in m. About ten times the one-step errors of docs/agreement.md.
TOLERANCES = {"arm_qpos": 0.01, "gripper_qpos": 0.002, "tcp_pos": 0.005, "obj_pos": 0.005}
#: The task flags compared step by step (those the env's `info` has).
FLAGS = ("is_grasped", "is_obj_grasped", "is_peg_grasped", "is_robot_static", "is_cube_placed",
         "is_peg_cube_fit", "is_obj_placed", "is_obj_on_goal", "success")
#: The flags that say the gripper holds the task's object (one per task).
GRASP_FLAGS = ("is_grasped", "is_obj_grasped", "is_peg_grasped")


def grasped(flags):
    """Whether a snapshot's flags say the object is held (any task's grasp flag)."""
    return any(flags.get(k, False) for k in GRASP_FLAGS)


#: Readings reported per episode in `open_action_gap`, the largest first.
TOP_READINGS = 3


def reading_groups(layout, joint_names):
    """{reading: observation indices} of a state observation: one reading per joint in the
    `agent/qpos` and `agent/qvel` entries (named `agent/qpos/<joint>`), one per other entry
    of `layout` ((name, start, end) triples, mjskill's `obs_layout`)."""
    groups = {}
    for name, start, end in layout:
        if name in ("agent/qpos", "agent/qvel") and end - start == len(joint_names):
            for k, joint in enumerate(joint_names):
                groups[f"{name}/{joint}"] = [start + k]
        else:
            groups[name] = list(range(start, end))
    return groups


def action_readings(policy_fn, obs_ref, obs_other, groups):
    """How far each reading moves the action: the largest |change| of `policy_fn`'s action
    when `obs_ref` takes that reading's entries from `obs_other`. Returns (the largest
    |difference| between the actions on the two observations, [(reading, change), ...]
    sorted from the largest change)."""
    obs_ref = np.asarray(obs_ref, np.float32).reshape(-1)
    obs_other = np.asarray(obs_other, np.float32).reshape(-1)
    base = np.asarray(policy_fn(obs_ref), np.float64)
    gap = float(np.max(np.abs(np.asarray(policy_fn(obs_other), np.float64) - base)))
    moves = []
    for name, idx in groups.items():
        o = obs_ref.copy()
        o[idx] = obs_other[idx]
        moves.append((name, float(np.max(np.abs(np.asarray(policy_fn(o), np.float64) - base)))))
    moves.sort(key=lambda m: -m[1])
    return gap, moves


def largest_action_gap(policy_fn, ms_obs, mj_obs, groups, until):
    """`action_readings` at each step before `until` (the open loop's first parting step,
    1-based, or None for every step): the step (0-based: the observation after that many
    actions) with the largest action difference, its size, and its top readings."""
    steps = range(len(ms_obs) if until is None else min(len(ms_obs), until))
    best = None
    for t in steps:
        gap, moves = action_readings(policy_fn, ms_obs[t], mj_obs[t], groups)
        if best is None or gap > best["gap"]:
            best = {"step": t, "gap": round(gap, 6),
                    "readings": [[n, round(v, 6)] for n, v in moves[:TOP_READINGS]]}
    return best


def ms_scalar(x):
    return to_numpy(x).reshape(-1)[0]


def ms_state_dict(env):
    """ManiSkill's state dict without the batch dimension, plus the drive targets PhysX
    keeps across steps (mjskill's `drive` entry)."""
    u = env.unwrapped
    sd = u.get_state_dict()
    out = {"actors": {k: to_numpy(v)[0] for k, v in sd["actors"].items()},
           "articulations": {k: to_numpy(v)[0] for k, v in sd["articulations"].items()}}
    if "controller" in sd:
        out["controller"] = {k: to_numpy(v)[0] for k, v in sd["controller"].items()
                             if to_numpy(v).size}
    robot = u.agent.robot
    out["drive"] = {"target_qpos": to_numpy(robot.get_drive_targets())[0],
                    "target_qvel": to_numpy(robot.get_drive_velocities())[0]}
    return out


class Snapshot:
    """The compared quantities of one simulator after a step."""

    def __init__(self, qpos, tcp, obj, info, qvel=None):
        self.qpos, self.tcp, self.obj = np.asarray(qpos, float), tcp, obj
        self.qvel = None if qvel is None else np.asarray(qvel, float)
        self.flags = {k: bool(v) for k, v in info.items() if k in FLAGS}


def ms_snapshot(env, obs, info, obj_name, tcp):
    u = env.unwrapped
    qpos = to_numpy(u.agent.robot.get_qpos())[0]
    obj = to_numpy(u.get_state_dict()["actors"][obj_name])[0][:3] if obj_name else None
    tcp_pos = to_numpy(obs).reshape(-1)[tcp] if tcp else None
    qvel = to_numpy(u.agent.robot.get_qvel())[0]
    return Snapshot(qpos, tcp_pos, obj, {k: ms_scalar(v) for k, v in info.items()}, qvel)


def mj_snapshot(env, obs, info, obj_name, tcp):
    sd = env.unwrapped.get_state_dict()
    art = np.asarray(next(iter(sd["articulations"].values())))
    n = (len(art) - 13) // 2
    obj = np.asarray(sd["actors"][obj_name])[:3] if obj_name else None
    tcp_pos = np.asarray(obs).reshape(-1)[tcp] if tcp else None
    return Snapshot(art[13:13 + n], tcp_pos, obj, info)


def ms_set_state(env, sd, tensor):
    """Sets a ManiSkill env (one sub-scene) to a state dict of mjskill's `get_state_dict`
    layout: actor and articulation states, the controller's state and the drive targets.
    `tensor` turns a float32 array into what ManiSkill takes (`torch.as_tensor`)."""

    def batched(x):
        if isinstance(x, dict):
            return {k: batched(v) for k, v in x.items()}
        return tensor(np.asarray(x, np.float32)[None])

    u = env.unwrapped
    u.set_state_dict({"actors": batched(sd["actors"]),
                      "articulations": batched(sd["articulations"])})
    if "controller" in sd:
        u.agent.set_controller_state(batched(sd["controller"]))
    robot = u.agent.robot
    joints = robot.get_active_joints()
    robot.set_joint_drive_targets(batched(sd["drive"]["target_qpos"]), joints)
    robot.set_joint_drive_velocity_targets(batched(sd["drive"]["target_qvel"]), joints)


def physx_steps(ms, seed, record, snaps, tensor):
    """Each of mjskill's steps taken by PhysX from mjskill's state (see the module docs):
    `record` holds the state dicts before the steps and the actions (`run_mjskill`), `snaps`
    mjskill's snapshots after them; `tensor` as for `ms_set_state`. Returns ManiSkill's
    success at the last step and at any step, and the number of steps where ManiSkill's
    `is_robot_static` differs from mjskill's."""
    last, any_, differ = False, False, 0
    for (sd, action), snap in zip(record, snaps):
        ms.reset(seed=seed)
        ms_set_state(ms, sd, tensor)
        _, _, _, _, ms_info = ms.step(tensor(action[None]))
        last = bool(ms_scalar(ms_info["success"]))
        any_ |= last
        if "is_robot_static" in snap.flags:
            differ += bool(ms_scalar(ms_info["is_robot_static"])) != snap.flags["is_robot_static"]
    return last, any_, differ


def robot_key(env):
    return next(iter(env.unwrapped.get_state_dict()["articulations"]))


def differences(a, b, arm):
    """{quantity: size} of the differences between two snapshots."""
    d = {"arm_qpos": float(np.max(np.abs(a.qpos[arm] - b.qpos[arm])))}
    grip = [i for i in range(len(a.qpos)) if i not in set(arm)]
    if grip:
        d["gripper_qpos"] = float(np.max(np.abs(a.qpos[grip] - b.qpos[grip])))
    if a.tcp is not None and b.tcp is not None:
        d["tcp_pos"] = float(np.linalg.norm(a.tcp - b.tcp))
    if a.obj is not None and b.obj is not None:
        d["obj_pos"] = float(np.linalg.norm(a.obj - b.obj))
    return d


def first_part(ms_snaps, mj_snaps, arm):
    """(step, quantity, value) of the first step (1-based) at which the two runs part."""
    for t, (a, b) in enumerate(zip(ms_snaps, mj_snaps), start=1):
        for q, v in differences(a, b, arm).items():
            if v > TOLERANCES[q]:
                return {"step": t, "quantity": q, "value": round(v, 6)}
        for k in sorted(set(a.flags) & set(b.flags)):
            if a.flags[k] != b.flags[k]:
                return {"step": t, "quantity": k, "maniskill": a.flags[k],
                        "mjskill": b.flags[k]}
    return None


def run_maniskill(env, policy, seed, low, high, obj_name, tcp):
    sess, inp, rank = policy
    obs, _ = env.reset(seed=seed)
    states, actions, snaps, seen = [], [], [], []
    while True:
        states.append(ms_state_dict(env))
        seen.append(to_numpy(obs).reshape(-1).astype(np.float32))
        a = act(sess, inp, rank, obs, low, high)
        obs, _, _, trunc, info = env.step(a[None])
        actions.append(a)
        snaps.append(ms_snapshot(env, obs, info, obj_name, tcp))
        if bool(ms_scalar(trunc)):
            return states, actions, snaps, seen


def run_mjskill(env, seed, actions, policy, obj_name, tcp, low, high, record=None):
    """Closed loop when `policy` is given, else the actions open loop. Returns the snapshots
    after each step and the observations before each. A `record` list gets each step's
    state dict before it and its action."""
    obs, _ = env.reset(seed=seed)
    snaps, seen = [], []
    for t in range(len(actions)):
        seen.append(np.asarray(obs, np.float32).reshape(-1))
        a = act(*policy, obs, low, high) if policy is not None else actions[t]
        if record is not None:
            record.append((env.unwrapped.get_state_dict(), np.asarray(a, np.float32)))
        obs, _, _, _, info = env.step(a)
        snaps.append(mj_snapshot(env, obs, info, obj_name, tcp))
    return snaps, seen


def resync_errors(env, seed, states, actions, ms_snaps, arm):
    """The largest arm-joint error after one step from each of ManiSkill's states."""
    env.reset(seed=seed)
    errs, held = [], []
    for sd, a, target in zip(states, actions, ms_snaps):
        env.unwrapped.set_state_dict(sd)
        env.step(a)
        after = mj_snapshot(env, None, {}, None, None)
        errs.append(float(np.max(np.abs(after.qpos[arm] - target.qpos[arm]))))
        held.append(grasped(target.flags))
    return errs, held


def held_steps(seed, states, actions, ms_snaps, held, per_episode):
    """Up to `per_episode` of an episode's held steps, spread evenly, as JSON-ready cases."""
    steps = [t for t, h in enumerate(held) if h]
    if len(steps) > per_episode:
        steps = [steps[round(i * (len(steps) - 1) / (per_episode - 1))] if per_episode > 1
                 else steps[0] for i in range(per_episode)]
    out = []
    for t in steps:
        sd = states[t]
        out.append({
            "seed": seed, "step": t,
            "state_dict": {k: ({n: np.asarray(x).tolist() for n, x in v.items()}
                               if isinstance(v, dict) else v) for k, v in sd.items()},
            "action": np.asarray(actions[t], float).tolist(),
            "qpos": ms_snaps[t].qpos.tolist(),
            "qvel": ms_snaps[t].qvel.tolist(),
            "is_robot_static": ms_snaps[t].flags.get("is_robot_static"),
        })
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("policy", help="ONNX policy file (mjskill's, with its metadata)")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--seed", type=int, default=10000, help="seed of the first episode")
    p.add_argument("--json", help="also write the JSON lines to this file")
    p.add_argument("--physx-steps", action="store_true",
                   help="also take each of mjskill's closed-loop steps in PhysX from "
                        "mjskill's state (about one ManiSkill reset and step per step)")
    p.add_argument("--record-held", metavar="FILE",
                   help="write ManiSkill's held steps (state dict with drive targets, action, "
                        "qpos and reported qvel after the step) as JSON, for tests")
    p.add_argument("--held-per-episode", type=int, default=3,
                   help="with --record-held: held steps kept per episode (spread evenly)")
    p.add_argument("--pinch-solver", default="mujoco",
                   help="mjskill's pinch_solver: mujoco (default) or physx_tgs")
    a = p.parse_args()
    if a.episodes < 1:
        sys.exit(f"--episodes must be at least 1, not {a.episodes}")

    sess, inp, rank, meta = load(a.policy)
    policy = (sess, inp, rank)
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401  (registers ManiSkill's envs)
    import mjskill  # noqa: F401  (registers mjskill's envs)
    import torch  # ManiSkill's own dependency

    env_id, robot = meta["env_id"], meta["robot_uids"]
    kw = dict(obs_mode="state", control_mode=meta["control_mode"])
    ms_robot = {} if env_id in FIXED_ROBOT else dict(robot_uids=robot)
    ms = gym.make(env_id, num_envs=1, sim_backend="physx_cpu", render_backend="none",
                  **ms_robot, **kw)
    mj = gym.make(f"mjskill/{env_id}", robot_uids=robot, pinch_solver=a.pinch_solver, **kw)
    space = ms.unwrapped.single_action_space
    low, high = np.asarray(space.low, np.float32), np.asarray(space.high, np.float32)
    obj_name = next((k for k in ("cube", "obj", "sphere") if k in
                     ms.unwrapped.get_state_dict()["actors"]), None)
    spec = mj.unwrapped._native.spec()
    n_joints = len(mj.unwrapped.get_state_dict()["articulations"][robot_key(mj)]) - 13
    arm = [i for i in range(n_joints // 2) if i not in set(spec["gripper_joints"])]
    # The TCP position: the first 3 entries of the state observation's tcp_pose.
    tcp = next((slice(a, a + 3) for name, a, _ in spec["obs_layout"] if "tcp_pose" in name),
               None)
    joint_names = [j.name for j in ms.unwrapped.agent.robot.get_active_joints()]
    groups = reading_groups(spec["obs_layout"], joint_names)

    def policy_fn(o):
        return act(sess, inp, rank, o, low, high)

    lines, out = [], open(a.json, "w") if a.json else None
    held_cases = []
    for k in range(a.episodes):
        seed = a.seed + k
        states, actions, ms_snaps, ms_obs = run_maniskill(ms, policy, seed, low, high,
                                                          obj_name, tcp)
        record = [] if a.physx_steps else None
        closed, _ = run_mjskill(mj, seed, actions, policy, obj_name, tcp, low, high, record)
        open_, open_obs = run_mjskill(mj, seed, actions, None, obj_name, tcp, low, high)
        errs, held = resync_errors(mj, seed, states, actions, ms_snaps, arm)
        if a.record_held:
            held_cases += held_steps(seed, states, actions, ms_snaps, held,
                                     a.held_per_episode)
        open_part = first_part(ms_snaps, open_, arm)
        line = {
            "seed": seed,
            "maniskill_success": ms_snaps[-1].flags.get("success"),
            "mjskill_success": closed[-1].flags.get("success"),
            "open_loop_success": open_[-1].flags.get("success"),
            "closed_first_part": first_part(ms_snaps, closed, arm),
            "open_first_part": open_part,
            "open_action_gap": largest_action_gap(
                policy_fn, ms_obs, open_obs, groups, open_part["step"] if open_part else None),
            "one_step_arm_error_first": errs[0],
            "one_step_arm_error_median": float(np.median(errs)),
            "one_step_arm_error_held_median": float(np.median([e for e, h in zip(errs, held)
                                                               if h])) if any(held) else None,
            "one_step_arm_error_free_max": max((e for e, h in zip(errs, held) if not h),
                                               default=None),
            "one_step_free_steps_over_5mrad": sum(e > 0.005 for e, h in zip(errs, held) if not h),
        }
        if a.physx_steps:
            (line["physx_step_success"], line["physx_step_success_any"],
             line["static_differs"]) = physx_steps(ms, seed, record, closed, torch.as_tensor)
        lines.append(line)
        print(json.dumps(line), flush=True)
        if out:
            out.write(json.dumps(line) + "\n")

    def median_step(key):
        steps = [ln[key]["step"] for ln in lines if ln[key]]
        return float(np.median(steps)) if steps else None

    def most_common(key):
        c = collections.Counter(ln[key]["quantity"] for ln in lines if ln[key])
        return c.most_common(1)[0][0] if c else None

    summary = {
        "summary": True, "policy": a.policy, "env": env_id, "robot": robot,
        "control_mode": meta["control_mode"], "episodes": a.episodes, "seed": a.seed,
        "pinch_solver": a.pinch_solver,
        "maniskill_successes": sum(bool(ln["maniskill_success"]) for ln in lines),
        "mjskill_successes": sum(bool(ln["mjskill_success"]) for ln in lines),
        "same_outcome": sum(bool(ln["maniskill_success"]) == bool(ln["mjskill_success"])
                            for ln in lines),
        "open_loop_same_outcome": sum(bool(ln["maniskill_success"]) ==
                                      bool(ln["open_loop_success"]) for ln in lines),
        "closed_median_first_part_step": median_step("closed_first_part"),
        "closed_most_common_quantity": most_common("closed_first_part"),
        "open_median_first_part_step": median_step("open_first_part"),
        "open_most_common_quantity": most_common("open_first_part"),
        "open_action_gap_median": float(np.median(
            [ln["open_action_gap"]["gap"] for ln in lines])),
        "open_action_gap_most_common_reading": collections.Counter(
            ln["open_action_gap"]["readings"][0][0] for ln in lines).most_common(1)[0][0],
        "one_step_arm_error_first_median": float(np.median(
            [ln["one_step_arm_error_first"] for ln in lines])),
        "one_step_arm_error_median": float(np.median(
            [ln["one_step_arm_error_median"] for ln in lines])),
        "one_step_arm_error_held_median": float(np.median(
            [ln["one_step_arm_error_held_median"] for ln in lines
             if ln["one_step_arm_error_held_median"] is not None] or [np.nan])),
        "episodes_with_free_steps_over_5mrad": sum(
            ln["one_step_free_steps_over_5mrad"] > 0 for ln in lines),
    }
    if a.physx_steps:
        summary["physx_step_successes"] = sum(ln["physx_step_success"] for ln in lines)
        summary["physx_step_successes_any"] = sum(ln["physx_step_success_any"] for ln in lines)
        summary["static_differs_median"] = float(np.median([ln["static_differs"]
                                                            for ln in lines]))
    print(json.dumps(summary))
    if a.record_held:
        import mani_skill
        with open(a.record_held, "w") as f:
            json.dump({"source": f"ManiSkill {mani_skill.__version__} (physx_cpu): {env_id}, "
                                 f"{robot}, {meta['control_mode']}; the policy "
                                 f"{Path(a.policy).name} closed loop from each seed; per held "
                                 "step (is_grasped after it) the state before it with the drive "
                                 "targets, its action, and the arm's qpos and reported qvel "
                                 "after it (written by examples/compare_in_maniskill.py "
                                 "--record-held)",
                       "cases": held_cases}, f)
    if out:
        out.write(json.dumps(summary) + "\n")
        out.close()


if __name__ == "__main__":
    main()

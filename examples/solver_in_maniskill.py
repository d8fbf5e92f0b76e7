"""Runs mjskill's scripted solver closed loop in ManiSkill 3, and measures how chaotic its
episodes are there: ManiSkill against itself, and ManiSkill's episodes replayed in mjskill.

    pip install mani_skill                         # where ManiSkill runs, plus mjskill's wheel
    python examples/solver_in_maniskill.py --pairs PushT-v1:panda_stick --episodes 50 \\
        --seed 1000 --perturb 1e-3 1e-4 1e-5

Closed loop: before every step mjskill takes ManiSkill's state (`set_state_dict`, the drive
targets PhysX holds included) and the solver (`MjskillEnv.solver_action`, the stateful
`--policy solver`, which keeps the plan it makes over an episode) gives the action for it;
ManiSkill steps with that action. Both envs run `--control-mode` (default `pd_joint_pos`, into
which mjskill converts any solver's own mode, so that every robot's episodes can be replayed
with noise on its arm targets).

The episodes' actions are then replayed open loop from the same seed:

* in ManiSkill as they are (`exact`: PhysX CPU repeats itself; every episode should end as it
  did closed loop);
* in ManiSkill with N(0, SIGMA) rad added to every arm joint target of every step, for each
  `--perturb SIGMA` (seeded noise, as `maniskill_outcomes.py --perturb` adds it): ManiSkill
  against itself, the agreement that a simulator
  which is not PhysX bit for bit can expect on these action sequences (docs/outcome-physics.md);
* in mjskill (`mjskill`): ManiSkill's closed-loop episodes replayed here, the reverse of
  `examples/maniskill_outcomes.py`'s forward direction.

Step by step (`one_step`): before each of ManiSkill's closed-loop steps, a second mjskill env
takes ManiSkill's state and the same action, with `--pinch-solver` (docs/physics.md). Its arm
joints after the step are compared with ManiSkill's (the median of the largest joint error, over
all steps and over the steps ManiSkill reports `is_grasped`), and on those held steps its
`is_robot_static` with ManiSkill's: how closely mjskill's step follows PhysX's from the same
states, with no closed loop in between. `mjskill_closed_loop` is the solver's own closed loop in
mjskill with that pinch solver, on the same seeds.

Success is `success` at the last step, as the outcome tables count it; the closed-loop lines also
give success at any step. Prints one JSON line per pair; `--json FILE` also writes them. Each
pair's envs are made once and reset for every episode; PhysX CPU keeps contact caches across
resets, so the replays run in a fresh env of their own, the exact ones first and in the closed
loop's order. Needs numpy, mani_skill and the mjskill Python package in one environment.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_in_maniskill import ms_scalar, ms_state_dict, to_numpy  # noqa: E402
from maniskill_outcomes import ARM_JOINTS, maniskill_env, replay  # noqa: E402


def make_mjskill(env_id, robot, mode, pinch_solver="mujoco"):
    import gymnasium as gym
    import mjskill  # noqa: F401  (registers mjskill's envs)

    return gym.make(f"mjskill/{env_id}", robot_uids=robot, obs_mode="state", control_mode=mode,
                    pinch_solver=pinch_solver)


class OneStep:
    """What one mjskill step from each of ManiSkill's states gives against ManiSkill's own step:
    per step the largest arm-joint error, whether ManiSkill reports the object grasped, and
    both simulators' `is_robot_static` (None where the task has no such flag)."""

    def __init__(self):
        self.errors, self.held, self.static = [], [], []

    def add(self, error, held, ms_static, mj_static):
        self.errors.append(float(error))
        self.held.append(bool(held))
        self.static.append((ms_static, mj_static))

    def summary(self):
        """Medians of the arm error (rad) over all steps and over the held ones, and on the
        held steps that have both verdicts, the static verdicts: ManiSkill's, mjskill's and
        how many agree."""
        held = [i for i, h in enumerate(self.held) if h]
        judged = [i for i in held if None not in self.static[i]]
        med = (lambda xs: float(np.median(xs)) if len(xs) else None)
        return {"steps": len(self.errors),
                "arm_error_median": med(self.errors),
                "held_steps": len(held),
                "arm_error_held_median": med([self.errors[i] for i in held]),
                "held_static_judged": len(judged),
                "held_static_maniskill": sum(self.static[i][0] for i in judged),
                "held_static_mjskill": sum(self.static[i][1] for i in judged),
                "held_static_same": sum(self.static[i][0] == self.static[i][1] for i in judged)}


def flag(info, key):
    """A task's flag from a step's info (ManiSkill's batched or mjskill's), or None where the
    task has no such flag."""
    return bool(ms_scalar(info[key])) if key in info else None


def arm_qpos_mjskill(env, n_arm):
    """The arm joints' positions of a mjskill env (its state dict's articulation entry)."""
    art = np.asarray(next(iter(env.unwrapped.get_state_dict()["articulations"].values())))
    return art[13:13 + n_arm]


def closed_loop(ms, mj, seed, follower=None, n_arm=0, one_step=None):
    """One episode of mjskill's solver acting on ManiSkill's states. With a `follower` (a
    mjskill env), it also takes each step from ManiSkill's state, and `one_step` (`OneStep`)
    collects how it compares with ManiSkill's step over the first `n_arm` joints. Returns
    (actions, success after each step)."""
    ms.reset(seed=seed)
    mj.reset(seed=seed)
    if follower is not None:
        follower.reset(seed=seed)
    actions, success = [], []
    while True:
        if actions:
            state = ms_state_dict(ms)
            mj.unwrapped.set_state_dict(state)
            if follower is not None:
                follower.unwrapped.set_state_dict(state)
        a = np.asarray(mj.unwrapped.solver_action(), np.float32)
        _, _, _, trunc, info = ms.step(a[None])
        if follower is not None:
            _, _, _, _, f_info = follower.step(a)
            ms_q = to_numpy(ms.unwrapped.agent.robot.get_qpos())[0][:n_arm]
            err = np.max(np.abs(ms_q - arm_qpos_mjskill(follower, n_arm)))
            one_step.add(err, flag(info, "is_grasped"), flag(info, "is_robot_static"),
                         flag(f_info, "is_robot_static"))
        actions.append(a)
        success.append(bool(ms_scalar(info["success"])))
        if bool(ms_scalar(trunc)):
            return np.array(actions), success


def mjskill_closed_loop(env, seed):
    """The solver's own episode in a mjskill env: (success at the last step, at any step)."""
    env.reset(seed=seed)
    any_, last = False, False
    while True:
        _, _, _, trunc, info = env.step(env.unwrapped.solver_action())
        last = bool(info["success"])
        any_ |= last
        if trunc:
            return last, any_


def replay_mjskill(env, seed, actions):
    """Final success of `actions` replayed open loop from `seed` in a mjskill env."""
    env.reset(seed=seed)
    info = {}
    for a in actions:
        _, _, _, _, info = env.step(a)
    return bool(info["success"])


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pairs", default="PushT-v1:panda_stick",
                   help="comma-separated ENV:ROBOT pairs (default PushT-v1:panda_stick)")
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--seed", type=int, default=1000, help="seed of the first episode")
    p.add_argument("--control-mode", default="pd_joint_pos",
                   help="both envs' control mode (default pd_joint_pos)")
    p.add_argument("--perturb", type=float, nargs="*", default=[1e-3], metavar="SIGMA",
                   help="arm-target noise levels (rad) of ManiSkill against itself (default 1e-3)")
    p.add_argument("--noise-seed", type=int, default=12345)
    p.add_argument("--pinch-solver", default="mujoco",
                   help="the pinch solver of the step-by-step env and of mjskill's own closed loop: "
                        "mujoco (default) or physx_tgs (docs/physics.md)")
    p.add_argument("--json", help="also write the JSON lines to this file")
    a = p.parse_args()
    if a.episodes < 1:
        sys.exit(f"--episodes must be at least 1, not {a.episodes}")
    if any(not np.isfinite(s) or s < 0 for s in a.perturb):
        sys.exit(f"--perturb takes finite noise levels >= 0, not {a.perturb}")
    pairs = []
    for item in a.pairs.split(","):
        env_id, _, robot = item.partition(":")
        if not robot:
            sys.exit(f"--pairs: {item!r} is not ENV:ROBOT")
        if robot not in ARM_JOINTS:
            sys.exit(f"--pairs: unknown robot {robot!r}; valid: {', '.join(sorted(ARM_JOINTS))}")
        pairs.append((env_id, robot))

    out = open(a.json, "w") if a.json else None
    for env_id, robot in pairs:
        mode = a.control_mode
        ms, mj = maniskill_env(env_id, robot, mode), make_mjskill(env_id, robot, mode)
        follower = make_mjskill(env_id, robot, mode, a.pinch_solver)
        seeds = range(a.seed, a.seed + a.episodes)
        one_step = OneStep()
        episodes = [closed_loop(ms, mj, s, follower, ARM_JOINTS[robot], one_step) for s in seeds]
        ms.close()
        final = [succ[-1] for _, succ in episodes]
        line = {"env": env_id, "robot": robot, "control_mode": mode, "seeds": [seeds[0], seeds[-1]],
                "pinch_solver": a.pinch_solver,
                "closed_loop_success_at_end": sum(final),
                "closed_loop_success_any_step": sum(any(succ) for _, succ in episodes),
                "one_step": one_step.summary()}
        own = [mjskill_closed_loop(follower, s) for s in seeds]
        follower.close()
        line["mjskill_closed_loop"] = {"success_at_end": sum(x for x, _ in own),
                                       "success_any_step": sum(y for _, y in own)}

        # One fresh env for every replay of the pair (maniskill_outcomes.replay's `reuse`),
        # the exact replays first, in the closed loop's order.
        exact = [replay(env_id, robot, mode, s, acts, reuse=True)[1]
                 for s, (acts, _) in zip(seeds, episodes)]
        line["exact_replay_same"] = sum(x == f for x, f in zip(exact, final))

        # The noise as `maniskill_outcomes.py --perturb` adds it: on the arm's part of a
        # `pd_joint_pos` action (its targets), else on the targets the arm controller sets.
        rng = np.random.default_rng(a.noise_seed)
        n_arm = ARM_JOINTS[robot]
        line["maniskill_against_itself"] = {}
        for sigma in a.perturb:
            same = 0
            for s, (acts, _), f in zip(seeds, episodes, final):
                if mode == "pd_joint_pos":
                    noisy = acts.copy()
                    noisy[:, :n_arm] += rng.normal(0.0, sigma, noisy[:, :n_arm].shape)
                    pert = replay(env_id, robot, mode, s, noisy, reuse=True)[1]
                else:
                    pert = replay(env_id, robot, mode, s, acts, reuse=True,
                                  target_noise=(rng, sigma))[1]
                same += pert == f
            line["maniskill_against_itself"][f"{sigma:g}"] = {"same_final_success": same}

        mine = [replay_mjskill(mj, s, acts) for s, (acts, _) in zip(seeds, episodes)]
        mj.close()
        line["mjskill_replay"] = {"successes": sum(mine),
                                  "same_final_success": sum(x == f for x, f in zip(mine, final))}
        print(json.dumps(line), flush=True)
        if out:
            out.write(json.dumps(line) + "\n")


if __name__ == "__main__":
    main()

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
  `--perturb SIGMA` (seeded noise): ManiSkill against itself, the agreement that a simulator
  which is not PhysX bit for bit can expect on these action sequences (docs/outcome-physics.md);
* in mjskill (`mjskill`): ManiSkill's closed-loop episodes replayed here, the reverse of
  `examples/maniskill_outcomes.py`'s forward direction.

Success is `success` at the last step, as the outcome tables count it; the closed-loop line also
gives success at any step. Prints one JSON line per pair; `--json FILE` also writes them. Each
pair's envs are made once and reused in order (PhysX CPU keeps contact caches across resets,
so the exact replay runs in a fresh env of its own, episodes in the same order). Needs numpy,
mani_skill and the mjskill Python package in one environment.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_in_maniskill import ms_scalar, ms_state_dict  # noqa: E402
from maniskill_outcomes import ARM_JOINTS, FIXED_ROBOT  # noqa: E402


def make_maniskill(env_id, robot, mode):
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401  (registers ManiSkill's envs)

    kw = dict(obs_mode="state", control_mode=mode, num_envs=1, sim_backend="physx_cpu")
    # PushT-v1's table scene whitens the table's render shapes, which need a renderer.
    if env_id != "PushT-v1":
        kw["render_backend"] = "none"
    if env_id not in FIXED_ROBOT:
        kw["robot_uids"] = robot
    return gym.make(env_id, **kw)


def make_mjskill(env_id, robot, mode):
    import gymnasium as gym
    import mjskill  # noqa: F401  (registers mjskill's envs)

    return gym.make(f"mjskill/{env_id}", robot_uids=robot, obs_mode="state", control_mode=mode)


def closed_loop(ms, mj, seed):
    """One episode of mjskill's solver acting on ManiSkill's states. Returns (actions, success
    after each step)."""
    ms.reset(seed=seed)
    mj.reset(seed=seed)
    actions, success = [], []
    while True:
        if actions:
            mj.unwrapped.set_state_dict(ms_state_dict(ms))
        a = np.asarray(mj.unwrapped.solver_action(), np.float32)
        _, _, _, trunc, info = ms.step(a[None])
        actions.append(a)
        success.append(bool(ms_scalar(info["success"])))
        if bool(ms_scalar(trunc)):
            return np.array(actions), success


def replay(env, seed, actions, batched):
    """Final success of `actions` replayed open loop from `seed`."""
    env.reset(seed=seed)
    info = {}
    for a in actions:
        _, _, _, _, info = env.step(a[None] if batched else a)
    return bool(ms_scalar(info["success"])) if batched else bool(info["success"])


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
        ms, mj = make_maniskill(env_id, robot, mode), make_mjskill(env_id, robot, mode)
        seeds = range(a.seed, a.seed + a.episodes)
        episodes = [closed_loop(ms, mj, s) for s in seeds]
        final = [succ[-1] for _, succ in episodes]
        line = {"env": env_id, "robot": robot, "control_mode": mode, "seeds": [seeds[0], seeds[-1]],
                "closed_loop_success_at_end": sum(final),
                "closed_loop_success_any_step": sum(any(succ) for _, succ in episodes)}

        exact_env = make_maniskill(env_id, robot, mode)
        exact = [replay(exact_env, s, acts, True) for s, (acts, _) in zip(seeds, episodes)]
        line["exact_replay_same"] = sum(x == f for x, f in zip(exact, final))

        n_arm = ARM_JOINTS[robot]
        rng = np.random.default_rng(a.noise_seed)
        line["maniskill_against_itself"] = {}
        for sigma in a.perturb:
            same = 0
            for s, (acts, _), f in zip(seeds, episodes, final):
                noisy = acts.copy()
                noisy[:, :n_arm] += rng.normal(0.0, sigma, noisy[:, :n_arm].shape).astype(np.float32)
                same += replay(exact_env, s, noisy, True) == f
            line["maniskill_against_itself"][f"{sigma:g}"] = {"same_final_success": same}

        mine = [replay(mj, s, acts, False) for s, (acts, _) in zip(seeds, episodes)]
        line["mjskill_replay"] = {"successes": sum(mine),
                                  "same_final_success": sum(x == f for x, f in zip(mine, final))}
        print(json.dumps(line), flush=True)
        if out:
            out.write(json.dumps(line) + "\n")
        ms.close()
        mj.close()
        exact_env.close()


if __name__ == "__main__":
    main()

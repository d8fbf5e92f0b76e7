"""Evaluates an mjskill policy file in the real ManiSkill 3 (SAPIEN/PhysX), closed loop: the
env, robot, control mode and obs mode come from the file's metadata, and the episodes use the
seeds `mjskill eval --policy` uses (seed, seed+1, ...), so the two success rates compare the
simulators on the same initial states.

    pip install mani_skill onnxruntime      # in an environment where ManiSkill runs
    python examples/eval_in_maniskill.py policy.onnx --episodes 100 --seed 0
    python examples/eval_in_maniskill.py policy.onnx --mjskill target/release/mjskill

Each episode runs to truncation (50 steps), as `mjskill eval` does; prints one JSON line with
the success rate (success at any step), the success-at-end rate and the mean return, and with
--mjskill also `mjskill eval --policy`'s report on the same seeds. PhysX keeps contact caches
across resets, so the figures depend on what the env went through before each episode:
`--history` runs the seeds in one env in order (the default, as `mjskill eval`), in reverse
order, or each in a new env. Needs numpy, onnxruntime and mani_skill (not mjskill).
"""

import argparse
import json
import subprocess
import sys

import numpy as np

KEYS = ("env_id", "robot_uids", "control_mode", "obs_mode")
#: `--history` choices: what each episode's env has been through before its reset.
HISTORIES = ("sequential", "reversed", "fresh")


def episode_seeds(seed, episodes, history):
    """The seeds in the order the episodes run: `seed`, `seed + 1`, ... (reversed for
    `--history reversed`)."""
    seeds = list(range(seed, seed + episodes))
    return seeds[::-1] if history == "reversed" else seeds
#: ManiSkill's envs that fix their robot (gym.make refuses robot_uids for them).
FIXED_ROBOT = {"PickCubeSO100-v1": "so100", "PickCubeWidowXAI-v1": "widowxai"}


def load(path):
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    sess = ort.InferenceSession(path, sess_options=opts, providers=["CPUExecutionProvider"])
    meta = dict(sess.get_modelmeta().custom_metadata_map)
    missing = [k for k in KEYS if k not in meta]
    if missing:
        sys.exit(f"policy file {path} lacks the metadata_props {', '.join(missing)}")
    if meta["obs_mode"] not in ("state", "state_dict"):
        sys.exit(f"policy file {path} has obs_mode {meta['obs_mode']!r}; expected state")
    (inp,) = sess.get_inputs()
    return sess, inp.name, len(inp.shape), meta


def to_numpy(x):
    if hasattr(x, "cpu"):
        x = x.cpu().numpy()
    return np.asarray(x)


def act(sess, inp, rank, obs, low, high):
    """The policy file's action for one observation (numpy or torch, any batch shape of one),
    clipped to the action space."""
    o = to_numpy(obs).astype(np.float32).reshape(1, -1)
    (a,) = sess.run(None, {inp: o if rank == 2 else o[0]})
    return np.clip(np.asarray(a, np.float32).reshape(-1), low, high)


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("policy", help="ONNX policy file")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    p.add_argument("--sim-backend", default="cpu", help="ManiSkill sim_backend (cpu or gpu)")
    p.add_argument("--reward-mode", default="normalized_dense")
    p.add_argument("--mjskill", help="mjskill binary: also run `mjskill eval --policy` on the seeds")
    p.add_argument("--history", choices=HISTORIES, default="sequential",
                   help="what each episode follows: sequential (default; one env, seeds in "
                        "order, as `mjskill eval`), reversed (one env, seeds in reverse order) "
                        "or fresh (a new env for every episode). PhysX keeps contact caches "
                        "across resets, so the success rates depend on it (docs/outcome-physics.md)")
    p.add_argument("--per-episode", action="store_true",
                   help="also report each episode (seed, success at any step, at the end, "
                        "return) under `per_episode`")
    a = p.parse_args()

    sess, inp, rank, meta = load(a.policy)
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401  (registers ManiSkill's envs)

    # PickCubeSO100-v1 and PickCubeWidowXAI-v1 fix their robot and refuse `robot_uids`.
    robot = {} if meta["env_id"] in FIXED_ROBOT else dict(robot_uids=meta["robot_uids"])
    if robot == {} and FIXED_ROBOT[meta["env_id"]] != meta["robot_uids"]:
        sys.exit(f"policy file {a.policy}: {meta['env_id']} is for {FIXED_ROBOT[meta['env_id']]}, "
                 f"not {meta['robot_uids']}")
    def make():
        return gym.make(meta["env_id"], num_envs=1, obs_mode="state", **robot,
                        control_mode=meta["control_mode"], reward_mode=a.reward_mode,
                        sim_backend=a.sim_backend)

    env = make()
    space = env.unwrapped.single_action_space if hasattr(env.unwrapped, "single_action_space") \
        else env.action_space
    low, high = np.asarray(space.low, np.float32), np.asarray(space.high, np.float32)
    obs_dim = int(np.prod(env.unwrapped.single_observation_space.shape))
    declared = sess.get_inputs()[0].shape[-1]
    if isinstance(declared, int) and declared != obs_dim:
        sys.exit(f"policy file {a.policy} takes observations of {declared} values, but "
                 f"ManiSkill's {meta['env_id']} gives {obs_dim}")
    successes = at_end = 0
    returns, first, episodes = [], [], []
    for seed in episode_seeds(a.seed, a.episodes, a.history):
        if a.history == "fresh" and episodes:
            env.close()
            env = make()
        obs, _ = env.reset(seed=seed)
        ret, ever, t = 0.0, False, 0
        while True:
            obs, r, term, trunc, info = env.step(act(sess, inp, rank, obs, low, high)[None])
            t += 1
            ret += float(to_numpy(r).reshape(-1)[0])
            success = bool(to_numpy(info["success"]).reshape(-1)[0])
            if success and not ever:
                first.append(t)
            ever |= success
            if bool(to_numpy(trunc).reshape(-1)[0]):
                break
        successes += ever
        at_end += success
        returns.append(ret)
        episodes.append({"seed": seed, "success": ever, "success_at_end": success,
                         "return": ret})
    episodes.sort(key=lambda e: e["seed"])
    report = {
        "simulator": "maniskill",
        "env": meta["env_id"],
        "robot": meta["robot_uids"],
        "control_mode": meta["control_mode"],
        "policy": a.policy,
        "episodes": a.episodes,
        "seed": a.seed,
        "history": a.history,
        "successes": int(successes),
        "success_rate": successes / a.episodes,
        "success_at_end_rate": at_end / a.episodes,
        "mean_return": float(np.mean(returns)),
        "mean_first_success_step": float(np.mean(first)) if first else None,
    }
    if a.per_episode:
        report["per_episode"] = episodes
    if a.mjskill:
        out = subprocess.run([a.mjskill, "eval", "--policy", a.policy, "--episodes",
                              str(a.episodes), "--seed", str(a.seed)],
                             check=True, capture_output=True, text=True).stdout
        report["mjskill"] = json.loads(out)
    print(json.dumps(report))


if __name__ == "__main__":
    main()

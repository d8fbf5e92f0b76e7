"""Env steps/s from Python, measured like `mjskill bench` measures them in Rust.

Single env: `--steps` steps of seeded uniform random actions in [-1, 1] after reset(seed=0),
no resets (as `mjskill bench`). Vector env (with --envs N --threads T): steps/N vector steps,
every env taking the same action row per step, after a warm-up of a tenth as many; the best
of three timed runs, each after reset(seed=0). Prints one JSON line.

    python examples/bench_python.py --envs 8 --threads 2 --steps 4000
"""

import argparse
import json
import time

import gymnasium as gym
import numpy as np

import mjskill


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--env", default="PickCube-v1")
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--envs", type=int)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()
    env = mjskill.MjskillEnv(a.env)
    dim = env.action_space.shape[0]
    actions = np.random.default_rng(0).uniform(-1, 1, (a.steps, dim)).astype(np.float32)
    env.reset(seed=0)
    for t in range(a.steps // 10):
        env.step(actions[t])
    env.reset(seed=0)
    t0 = time.perf_counter()
    for t in range(a.steps):
        env.step(actions[t])
    report = {"env": a.env, "steps": a.steps, "env_steps_per_s": a.steps / (time.perf_counter() - t0)}
    if a.envs:
        v = gym.make_vec(
            f"mjskill/{a.env}", num_envs=a.envs, num_threads=a.threads,
            vectorization_mode="vector_entry_point",
        )
        vsteps = max(a.steps // a.envs, 1)
        rows = np.repeat(actions[:, None, :], a.envs, axis=1)  # [steps × N × dim], made once
        v.reset(seed=0)
        for t in range(vsteps // 10 + 1):
            v.step(rows[t % a.steps])
        best = 0.0
        for _ in range(3):
            v.reset(seed=0)
            t0 = time.perf_counter()
            for t in range(vsteps):
                v.step(rows[t % a.steps])
            best = max(best, vsteps * a.envs / (time.perf_counter() - t0))
        report.update(envs=a.envs, threads=v.num_threads, vec_env_steps_per_s=best)
    print(json.dumps(report))


if __name__ == "__main__":
    main()

"""Evaluation of a policy in a vector env: one episode per env on fixed seeds, the policy's
mean action, an episode ended at its first success (mjskill's env always resets at
termination), so the success rate is ManiSkill's ``success_once``."""

from __future__ import annotations

import numpy as np


def run_episodes(envs, act, seed, max_steps):
    """Runs one episode in each env of ``envs`` (gymnasium's vector API; env i reset with seed
    ``seed + i``) for at most ``max_steps`` steps, each action ``act(obs)`` (a batch of
    observations in, a batch of actions out); returns (success rate, mean return)."""
    obs, _ = envs.reset(seed=seed)
    n = envs.num_envs
    done = np.zeros(n, bool)
    success = np.zeros(n, bool)
    ret = np.zeros(n)
    for _ in range(max_steps):
        obs, r, term, trunc, _ = envs.step(act(obs))
        ret += np.where(done, 0.0, r)
        success |= term & ~done
        done |= term | trunc
        if done.all():
            break
    return float(success.mean()), float(ret.mean())

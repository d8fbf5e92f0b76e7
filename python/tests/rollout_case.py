"""The native-rollout cases that the Ray tests run both sharded and in one process
(test_rollout.py, and test_ray_cluster.py on two Ray nodes through ray_two_nodes.py), so that
the two sides are the same by construction."""

from pathlib import Path

import numpy as np

from mjskill import GaussianMlp

KW = dict(max_episode_steps=6)


def params(obs_dim, act_dim, seed=0, hidden=16):
    """GaussianMlp keyword arguments with seeded weights (numpy only)."""
    r = np.random.default_rng(seed)
    layers = [
        (r.normal(0, 0.4, (obs_dim, hidden)).astype(np.float32),
         r.normal(0, 0.1, hidden).astype(np.float32)),
        (r.normal(0, 1.5, (hidden, act_dim)).astype(np.float32),
         r.normal(0, 0.1, act_dim).astype(np.float32)),
    ]
    return dict(layers=layers, obs_mean=r.normal(0, 0.1, obs_dim),
                obs_std=r.uniform(0.5, 2.0, obs_dim), obs_clip=10.0,
                std=np.full(act_dim, 0.3, np.float32), seed=7)


def rollout(vec, p, steps, first_step=0, env_offset=0):
    """``steps`` native rollout steps of ``vec`` with the policy ``p``: (buffers, last obs)."""
    buf = vec.rollout_buffers(steps)
    last = vec.rollout(GaussianMlp(**p, env_offset=env_offset), first_step, buf)
    return buf, last


# The two-node case (test_ray_cluster.py).
ENV_ID = "PickCube-v1"
NUM_ENVS = 5  # uneven shares on the two actors: 3 + 2 envs
RESET_SEED = 9
STEPS = 7  # per rollout call; 6-step episodes, so every env resets within a call
ITERATIONS = 2


def rollout_params(envs) -> list[dict]:
    """The policy of each rollout call: seeded GaussianMlp weights for ``envs``' spaces."""
    obs_dim = envs.single_observation_space.shape[0]
    act_dim = envs.single_action_space.shape[0]
    return [params(obs_dim, act_dim, seed=it) for it in range(ITERATIONS)]


def ppo_args(out: Path) -> list[str]:
    """examples/ppo.py's arguments for two small iterations (6 envs × 8 steps, 96 steps),
    one env thread and one torch thread, native rollouts."""
    return ["--env-id", ENV_ID, "--num-envs", "6", "--num-steps", "8", "--num-minibatches",
            "2", "--total-timesteps", "96", "--num-eval-envs", "2", "--eval-freq", "100",
            "--num-threads", "1", "--torch-threads", "1", "--hidden", "32", "32", "--rollout",
            "native", "--out", str(out)]

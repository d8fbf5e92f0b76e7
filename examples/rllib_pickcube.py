"""RLlib PPO on mjskill envs (an example configuration; not run in CI: RLlib needs torch).

Each RLlib env runner makes its envs with ``gym.make`` through a registered creator, so the
same script trains on a laptop (``ray.init()``) or a cluster (``RAY_ADDRESS=...``). The
settings follow ManiSkill's PPO baseline for PickCube (gamma 0.8, lambda 0.9, 50-step
episodes, normalized dense reward).

    pip install 'mjskill[ray]' 'ray[rllib]' torch
    python examples/rllib_pickcube.py --iterations 200 --env-runners 2
"""

import argparse

import gymnasium as gym
import ray
from ray.rllib.algorithms.ppo import PPOConfig
from ray.tune.registry import register_env


def make_env(config):
    import mjskill  # noqa: F401  (registers the envs inside each env runner process)

    return gym.make(
        f"mjskill/{config.get('env_id', 'PickCube-v1')}",
        robot_uids=config.get("robot_uids", "panda"),
        obs_mode="state",
        control_mode=config.get("control_mode", "pd_joint_delta_pos"),
        reward_mode="normalized_dense",
        max_episode_steps=50,
    )


def build_config(env_runners: int = 2, envs_per_runner: int = 8) -> PPOConfig:
    register_env("mjskill", make_env)
    return (
        PPOConfig()
        .environment("mjskill", env_config={"env_id": "PickCube-v1", "robot_uids": "panda"})
        .env_runners(num_env_runners=env_runners, num_envs_per_env_runner=envs_per_runner)
        .training(
            gamma=0.8,
            lambda_=0.9,
            lr=3e-4,
            train_batch_size_per_learner=env_runners * envs_per_runner * 50,
            minibatch_size=400,
            num_epochs=4,
            clip_param=0.2,
            vf_loss_coeff=0.5,
        )
        .rl_module(model_config={"fcnet_hiddens": [256, 256, 256], "fcnet_activation": "tanh"})
    )


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--iterations", type=int, default=200)
    p.add_argument("--env-runners", type=int, default=2)
    a = p.parse_args()
    ray.init()
    algo = build_config(a.env_runners).build_algo()
    for i in range(a.iterations):
        r = algo.train()
        runners = r.get("env_runners", {})
        print(i, runners.get("episode_return_mean"), runners.get("num_env_steps_sampled_lifetime"))


if __name__ == "__main__":
    main()

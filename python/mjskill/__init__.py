"""mjskill: ManiSkill3's tabletop tasks on MuJoCo 2.2 as gymnasium envs.

``import mjskill`` registers every env as ``mjskill/<EnvId>`` (e.g. ``mjskill/PickCube-v1``)
with gymnasium: ``gym.make`` gives a :class:`MjskillEnv` (with ``num_envs=N > 1``
ManiSkill's batched env, :class:`MjskillBatchedEnv`, which :class:`ManiSkillVectorEnv`
wraps), ``gym.make_vec(...,
vectorization_mode="vector_entry_point", num_envs=N, num_threads=T)`` the native
:class:`MjskillVectorEnv`. :mod:`mjskill.ray` (extra ``mjskill[ray]``) shards rollouts by
seed range across Ray workers. :class:`GaussianMlp` is PPO's actor evaluated inside the native
vector env's threads (:meth:`MjskillVectorEnv.rollout`).
"""

from __future__ import annotations

import gymnasium as gym

from . import _native
from ._native import GaussianMlp
from .batched import ManiSkillVectorEnv, MjskillBatchedEnv
from .entry_points import make_env, make_vector_env
from .envs import MjskillEnv, MjskillVectorEnv

__all__ = [
    "GaussianMlp",
    "ManiSkillVectorEnv",
    "MjskillBatchedEnv",
    "MjskillEnv",
    "MjskillVectorEnv",
    "make_env",
    "make_vector_env",
    "registered",
    "STATE_EXPERTS",
]
__version__ = _native.__version__
#: The (env id, robot, the expert's own control mode) pairs whose envs have
#: :meth:`MjskillEnv.expert_action`: labels that are a function of the state (DAgger).
STATE_EXPERTS: tuple[tuple[str, str, str], ...] = tuple(_native.state_experts())


def registered() -> list[tuple[str, str]]:
    """Every ``(gymnasium id, robot)`` pair that can be made."""
    return [(f"mjskill/{env_id}", r) for env_id, robots, _ in _native.registry() for r in robots]


def _register() -> None:
    for env_id, _robots, max_steps in _native.registry():
        gid = f"mjskill/{env_id}"
        if gid in gym.registry:
            continue
        gym.register(
            id=gid,
            entry_point="mjskill.entry_points:make_env",
            vector_entry_point="mjskill.entry_points:make_vector_env",
            max_episode_steps=max_steps,
            # Seeded resets and steps are deterministic, but an unseeded reset draws the
            # placement from the env's own "global torch generator", which a seeded reset
            # does not reseed (as in ManiSkill), so reset(seed=s); reset() is not a function
            # of s alone. gymnasium's flag for that is `nondeterministic`.
            nondeterministic=True,
            kwargs={"env_id": env_id},
            # gym.make(..., num_envs=N > 1) gives the batched env, whose array rewards and
            # flags gymnasium's PassiveEnvChecker would warn about (ManiSkill registers its
            # envs the same way); make_env puts the checker around a single env itself.
            disable_env_checker=True,
        )


_register()

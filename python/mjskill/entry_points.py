"""gymnasium's entry points of the ``mjskill/<EnvId>`` ids: ``gym.make`` calls
:func:`make_env` (one :class:`~mjskill.MjskillEnv`, or with ``num_envs > 1`` the batched
:class:`~mjskill.MjskillBatchedEnv`), ``gym.make_vec(..., vectorization_mode=
"vector_entry_point")`` calls :func:`make_vector_env`."""

from __future__ import annotations

import gymnasium as gym

from ._common import UNLIMITED, _check_count, check_sim_backend
from .batched import MjskillBatchedEnv
from .envs import MjskillEnv, MjskillVectorEnv


def make_env(num_envs: int = 1, **kwargs):
    """``gym.make`` entry point.

    ``num_envs=1`` (the default): one :class:`MjskillEnv` in gymnasium's
    ``PassiveEnvChecker`` (the ids are registered with the checker off, for the batched env);
    its own episode limit is lifted, because gymnasium's ``TimeLimit`` (``max_episode_steps``,
    default 50) truncates, as in ManiSkill. ``num_envs > 1`` (ManiSkill's ``gym.make(...,
    num_envs=N)``): the batched :class:`mjskill.batched.MjskillBatchedEnv`, which truncates
    each env itself (it disarms gymnasium's ``TimeLimit``). ManiSkill's ``sim_backend``
    keyword is accepted and checked (mjskill simulates with MuJoCo on the CPU), and
    ``reconfiguration_freq`` applies as in ManiSkill (PegInsertionSide-v1's shapes; the other
    scenes are fixed).
    """
    num_envs = _check_count("num_envs", num_envs)
    if num_envs > 1:
        return MjskillBatchedEnv(num_envs=int(num_envs), **kwargs)
    check_sim_backend(kwargs.pop("sim_backend", "auto"))
    batched_only = sorted({"num_threads", "array_backend"} & set(kwargs))
    if batched_only:
        env_id = kwargs.get("env_id", "PickCube-v1")
        raise ValueError(
            f"{', '.join(batched_only)} apply to the batched env (num_envs > 1); "
            f"gym.make('mjskill/{env_id}', num_envs=1) is one MjskillEnv (numpy values)"
        )
    kwargs.setdefault("max_episode_steps", UNLIMITED)
    return gym.wrappers.PassiveEnvChecker(MjskillEnv(**kwargs))


def make_vector_env(**kwargs) -> MjskillVectorEnv:
    """``gym.make_vec(..., vectorization_mode="vector_entry_point")`` entry point."""
    return MjskillVectorEnv(**kwargs)

"""``gym.make("mjskill/<EnvId>", num_envs=N)``: N envs as one batched ``gymnasium.Env``, with
ManiSkill's conventions, so that a ManiSkill training script ports by changing the env id.

ManiSkill's ``gym.make(env_id, num_envs=N)`` returns its batched ``BaseEnv``: observations,
rewards and flags carry a leading ``[N]`` dimension (torch tensors), an env whose episode
ended keeps stepping until the caller resets it (``reset(options={"env_idx": idx})`` resets
a subset), truncation is per env (``elapsed_steps >= max_episode_steps``), and
``ManiSkillVectorEnv`` wraps it to add autoreset. :class:`MjskillBatchedEnv` is that, over
the native vector env with its next-step autoreset switched off.

gymnasium's ``make`` wraps every env in ``TimeLimit``, whose scalar ``truncated = True`` would
end all N episodes at once. ManiSkill registers an extra wrapper that removes it, but a
registration with additional wrappers makes ``gym.make_vec`` refuse the ids' vector entry
point (the native vector env), so mjskill disarms it instead: on every ``reset`` the batched
env looks for the ``TimeLimit`` wrappers around it on the call stack, takes their
``max_episode_steps`` (``gym.make``'s, default the registered 50) as its own per-env limit
and sets their step counter so far back that they never fire. gymnasium's
``PassiveEnvChecker`` (which expects scalar rewards and flags) is not applied to the batched
env (the ids are registered with the checker off and the single env adds it itself).
``num_envs=1`` stays the single :class:`~mjskill.MjskillEnv`.
"""

from __future__ import annotations

import os
import sys
import weakref
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector.utils import batch_space

from . import _native
from ._common import (
    DEFAULT_QPOS_NOISE,
    DEFAULT_PINCH_SOLVER,
    DEFAULT_SIM_FREQ,
    RENDER_FPS,
    RENDER_MODES,
    SIM_BACKENDS,
    UNLIMITED,
    _as_actions,
    _check_count,
    _check_depth_dtype,
    _check_render_mode,
    _check_seed,
    _describe,
    _merge_components,
    _tensor_to_numpy,
    check_reconfiguration_freq,
    check_sim_backend,
    env_kwargs,
    live,
    reconfigure_option,
)

__all__ = [
    "ARRAY_BACKENDS",
    "RESET_OPTIONS",
    "SIM_BACKENDS",
    "UNLIMITED",
    "ManiSkillVectorEnv",
    "MjskillBatchedEnv",
    "check_reconfiguration_freq",
    "check_sim_backend",
]

ARRAY_BACKENDS = ["torch", "numpy"]
"""What the batched env returns: torch tensors on the CPU (ManiSkill's convention, the
default) or numpy arrays."""

RESET_OPTIONS = ["env_idx", "reconfigure"]
"""ManiSkill's ``reset`` options the batched env takes."""

_MAX_WRAPPER_DEPTH = 32
"""How many callers are searched for gymnasium's ``make`` and ``TimeLimit`` (:func:`_callers`)."""


def _callers(depth: int):
    """The frames of the callers, from ``depth`` levels above the function that iterates
    this generator (1: its caller) on, at most :data:`_MAX_WRAPPER_DEPTH` of them. The one place the batched env reads the
    call stack: gymnasium passes it neither ``make``'s ``max_episode_steps=-1`` (it only
    leaves its ``TimeLimit`` out, and ``env.spec``, which ``make`` sets after the env is
    built, says ``None`` either way) nor the ``TimeLimit`` around it."""
    frame = sys._getframe(depth + 1)
    for _ in range(_MAX_WRAPPER_DEPTH):
        if frame is None:
            return
        yield frame
        frame = frame.f_back


def _made_without_time_limit() -> bool:
    """Whether this env is being made by ``gym.make(..., max_episode_steps=-1)``: read from
    ``gymnasium.make``'s frame among the callers."""
    for frame in _callers(1):
        if frame.f_code.co_name == "make" and frame.f_globals.get("__name__", "").startswith(
                "gymnasium"):
            return frame.f_locals.get("max_episode_steps") == -1
    return False


class MjskillBatchedEnv(gym.Env):
    """N mjskill envs as one batched ``gymnasium.Env`` with ManiSkill's conventions.

    ``gym.make("mjskill/PickCube-v1", num_envs=N, ...)`` builds one (same keywords as the
    single env, plus ``num_threads``, default all cores, and ``array_backend``). Values have a
    leading ``[N]`` dimension: observations ``[N, D]`` float32 (visual modes: ``Dict`` of
    ``[N, ...]``), rewards ``[N]`` float32, ``terminated`` (success) and ``truncated``
    (``elapsed_steps >= max_episode_steps``) ``[N]`` bool, ``info[key]`` ``[N]`` plus
    ``info["elapsed_steps"]``. They are torch tensors on the CPU (``array_backend="torch"``, as
    ManiSkill; needs torch) or numpy arrays (``array_backend="numpy"``). Actions may be either.

    As ManiSkill's batched env, it does not reset by itself: an env whose episode ended keeps
    stepping (``elapsed_steps`` counts on, ``truncated`` stays true) until
    ``reset(options={"env_idx": idx})`` resets it — which is what ManiSkill's
    ``ManiSkillVectorEnv`` (and :class:`mjskill.ManiSkillVectorEnv`) do on every end.
    ``reset(seed=s)`` seeds env i with ``s + i`` (a partial reset seeds the envs it resets
    the same way), so env i's episode is the single env's with seed ``s + i``.
    """

    def __init__(
        self,
        env_id: str = "PickCube-v1",
        num_envs: int = 2,
        num_threads: int | None = None,
        robot_uids: str | None = None,
        obs_mode: str = "state",
        control_mode: str | None = None,
        reward_mode: str = "normalized_dense",
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
        robot_init_qpos_noise: float = DEFAULT_QPOS_NOISE,
        sim_freq: int = DEFAULT_SIM_FREQ,
        pinch_solver: str = DEFAULT_PINCH_SOLVER,
        depth_dtype: str = "float32",
        array_backend: str = "torch",
        sim_backend: str = "auto",
        reconfiguration_freq: int | None = None,
    ):
        _check_depth_dtype(depth_dtype)
        check_sim_backend(sim_backend)
        self.reconfiguration_freq = check_reconfiguration_freq(reconfiguration_freq, num_envs)
        if array_backend not in ARRAY_BACKENDS:
            raise ValueError(
                f"unknown array_backend {array_backend!r}; valid: {', '.join(ARRAY_BACKENDS)}"
            )
        _check_render_mode(render_mode)
        num_envs = _check_count("num_envs", num_envs)
        if num_threads is not None:
            num_threads = _check_count("num_threads", num_threads)
        self._torch = None
        if array_backend == "torch":
            try:
                import torch
            except ImportError as e:
                raise ImportError(
                    f"gym.make('mjskill/{env_id}', num_envs={num_envs}) returns torch tensors, as "
                    "ManiSkill's batched env does, and needs torch (pip install torch); pass "
                    "array_backend='numpy' for numpy arrays, or use gym.make_vec for gymnasium's "
                    "VectorEnv"
                ) from e
            self._torch = torch
            self.device = torch.device("cpu")
        else:
            self.device = None
        self.array_backend = array_backend
        self.sim_backend = sim_backend
        # The native envs never redraw shapes by themselves: this env keeps ManiSkill's one
        # reset counter and asks for a redraw when it is due (see reset).
        self._kwargs = dict(env_id=env_id, **dict(env_kwargs(locals()), reconfiguration_freq=0))
        # The static description (layout, bounds, default episode length) from one env.
        spec = _native.Env(**self._kwargs).spec()
        threads = num_threads if num_threads is not None else (os.cpu_count() or 1)
        # The native envs never truncate (the limit is applied here) and never reset by
        # themselves: ManiSkill's batched env keeps stepping an ended episode.
        self._native = _native.VecEnv(
            num_envs=int(num_envs),
            num_threads=int(min(threads, num_envs)),
            autoreset=False,
            **dict(self._kwargs, max_episode_steps=UNLIMITED),
        )
        self.num_envs = int(num_envs)
        self.num_threads = self._native.num_threads
        self.render_mode = render_mode
        self.metadata = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS}
        self.max_episode_steps = int(spec["max_episode_steps"])
        # PegInsertionSide-v1 draws its shapes at every reset (each env from its own seed).
        self._reconfigures = bool(spec["reconfigures"])
        # ManiSkill's _reconfig_counter after the construction's reconfiguring reset.
        freq = self.reconfiguration_freq
        self._reconfig_counter = freq - 1 if freq != 0 else 0
        if max_episode_steps is None and _made_without_time_limit():
            # gym.make(..., max_episode_steps=-1): gymnasium's "no time limit", as for the
            # single env (and -1 given here or to make_vec).
            self.max_episode_steps = UNLIMITED
        self.single_action_space = _describe(self, spec, depth_dtype)
        self.single_observation_space = self._layout.space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._elapsed = np.zeros(self.num_envs, np.int64)
        self._time_limits: weakref.WeakSet = weakref.WeakSet()

    # -- conversions -----------------------------------------------------------------------
    def _out(self, x: Any) -> Any:
        """A numpy value (or a dict of them) in the env's array backend."""
        if isinstance(x, dict):
            return {k: self._out(v) for k, v in x.items()}
        if self._torch is None or not isinstance(x, np.ndarray) or x.dtype == object:
            return x
        return self._torch.from_numpy(np.ascontiguousarray(x))

    def _info(self, native_info: dict) -> dict:
        # ManiSkill's info has no gymnasium "_key" masks; MuJoCo warnings keep theirs.
        info = {k: v for k, v in native_info.items() if not k.startswith("_") or k == "_warnings"}
        # A vector value (PegInsertionSide's `peg_head_pos_at_hole`): one [N, k] array.
        _merge_components(info)
        info["elapsed_steps"] = self._elapsed.astype(np.int32)
        return self._out(info)

    def _index_mask(self, env_idx: Any) -> np.ndarray:
        idx = np.asarray(_tensor_to_numpy(env_idx, "env_idx"))
        mask = np.zeros(self.num_envs, bool)
        if idx.size == 0:
            # No envs to reset (an empty list is float64 to numpy, not an index array).
            return mask
        if idx.dtype == bool:
            if idx.shape != (self.num_envs,):
                raise ValueError(
                    f"env_idx is a boolean mask of shape {idx.shape}, expected ({self.num_envs},)"
                )
            return idx.copy()
        if idx.dtype.kind not in "iu":
            raise TypeError(f"env_idx must hold env indices (ints), got dtype {idx.dtype}")
        idx = idx.reshape(-1)
        bad = idx[(idx < 0) | (idx >= self.num_envs)]
        if bad.size:
            raise ValueError(
                f"env_idx {int(bad[0])} is out of range: the envs are 0..{self.num_envs - 1}"
            )
        mask[idx] = True
        return mask

    # -- gymnasium API ---------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        """Resets every env, or with ``options={"env_idx": idx}`` (indices or an ``[N]`` bool
        mask, numpy or torch) only those; env i gets seed ``seed + i``. Returns the
        observations and info of all N envs."""
        native = self._live()
        options = reconfigure_option(options, tuple(RESET_OPTIONS))
        freq = self.reconfiguration_freq
        reconfigure = bool(options.get("reconfigure", False)) or (
            self._reconfig_counter == 0 and freq != 0
        )
        if reconfigure and options.get("env_idx") is not None:
            raise RuntimeError(
                "Cannot do a partial reset and reconfigure the environment. You must do one "
                "or the other (ManiSkill's rule: options env_idx and reconfigure=True)"
            )
        if isinstance(seed, (list, tuple)):
            seeds = [_check_seed(s) for s in seed]
            if len(seeds) != self.num_envs or any(s != seeds[0] + i for i, s in enumerate(seeds)):
                raise ValueError(
                    f"seed list {list(seed)} is not supported: env i is seeded with s + i, so "
                    f"give one int s or the list [s, s+1, ..., s+{self.num_envs - 1}]"
                )
            seed = seeds[0]
        seed = _check_seed(seed)
        if seed is not None:
            self._np_random, self._np_random_seed = gym.utils.seeding.np_random(seed)
        self._disarm_time_limits()
        if reconfigure:
            self._reconfig_counter = freq
        if freq != 0:
            self._reconfig_counter -= 1
        if options.get("env_idx") is None:
            obs, info = native.reset(seed, reconfigure)
            self._elapsed[:] = 0
        else:
            mask = self._index_mask(options["env_idx"])
            obs, info = native.reset_envs(mask, seed)
            self._elapsed[mask] = 0
        info = self._info(info)
        # Whether the scene was rebuilt (only PegInsertionSide-v1's shapes are redrawn).
        info["reconfigure"] = reconfigure and self._reconfigures
        return self._out(self._layout.batch(obs, native)), info

    def _disarm_time_limits(self) -> None:
        """Finds gymnasium ``TimeLimit`` wrappers of this env among the callers of ``reset``
        (``gym.make`` puts one outside it; ``TimeLimit.reset`` zeroes its counter and then calls
        in here), takes the smallest limit as the per-env ``max_episode_steps`` and moves their
        counters back by 2**62 steps, so their scalar ``truncated = True`` never fires."""
        for frame in _callers(2):
            w = frame.f_locals.get("self")
            if isinstance(w, gym.wrappers.TimeLimit) and w.unwrapped is self:
                self._time_limits.add(w)
        if self._time_limits:
            self.max_episode_steps = min(int(w._max_episode_steps) for w in self._time_limits)
            for w in self._time_limits:
                w._elapsed_steps = -(2**62)

    def step(self, action):
        native = self._live()
        a = _as_actions(action, 2)
        obs, reward, terminated, _, info = native.step(a)
        self._elapsed += 1
        truncated = self._elapsed >= self.max_episode_steps
        return (
            self._out(self._layout.batch(obs, native)),
            self._out(reward),
            self._out(terminated),
            self._out(truncated),
            self._info(info),
        )

    def render(self):
        raise RuntimeError(
            "the batched env renders no human-camera frames; render with a single env "
            f"(gym.make('mjskill/{self._kwargs['env_id']}', render_mode='rgb_array')), or use a "
            "visual obs_mode for the sensor cameras' images of every env"
        )

    def close(self) -> None:
        """Frees the N envs (each owns its MuJoCo model and data). Closing again does
        nothing; ``reset`` and ``step`` after it raise ``RuntimeError``."""
        self._native = None

    def _live(self) -> Any:
        """The native envs, or a ``RuntimeError`` once the env is closed."""
        what = f"this batched mjskill/{self._kwargs['env_id']} env (num_envs={self.num_envs})"
        return live(self._native, what, "make a new one with gym.make")

    # -- ManiSkill-style attributes --------------------------------------------------------
    @property
    def elapsed_steps(self):
        """Steps of each env's current episode, ``[N]`` int32."""
        return self._out(self._elapsed.astype(np.int32))

    @property
    def gpu_sim_enabled(self) -> bool:
        return False


def _copy(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _copy(v) for k, v in x.items()}
    if hasattr(x, "clone"):
        return x.clone()
    return x.copy() if isinstance(x, np.ndarray) else x


class ManiSkillVectorEnv(gym.vector.VectorEnv):
    """ManiSkill's ``ManiSkillVectorEnv`` conventions over a batched env (``gym.make(id,
    num_envs=N)``), for scripts written against ManiSkill: ``from mjskill import
    ManiSkillVectorEnv`` replaces ``from mani_skill.vector.wrappers.gymnasium import
    ManiSkillVectorEnv`` (ManiSkill's own class wraps :class:`MjskillBatchedEnv` as well).

    ``auto_reset`` (default on): gymnasium's *same-step* autoreset — the envs that ended
    (``terminated | truncated``; with ``ignore_terminations`` only ``truncated``) are reset
    within the step, the returned observation is the new episode's first, and
    ``info["final_observation"]`` / ``info["final_info"]`` hold the ended step's observation
    and info, with the mask ``info["_final_info"]``. ``record_metrics`` adds
    ``info["episode"]``: ``success_once``, ``return``, ``episode_len``, ``reward`` (return per
    step) and, with ``ignore_terminations``, ``success_at_end``. Works with either array
    backend; ``env`` may also be an env id, made with ``num_envs`` and ``**kwargs``.
    """

    def __init__(
        self,
        env: gym.Env | str,
        num_envs: int | None = None,
        auto_reset: bool = True,
        ignore_terminations: bool = False,
        record_metrics: bool = False,
        **kwargs: Any,
    ):
        if isinstance(env, str):
            env = gym.make(env, num_envs=num_envs if num_envs is not None else 1, **kwargs)
        base = env.unwrapped
        if not isinstance(base, MjskillBatchedEnv):
            raise TypeError(
                "ManiSkillVectorEnv wraps the batched env of gym.make('mjskill/<EnvId>', "
                f"num_envs=N) with N > 1, not {type(base).__name__}"
            )
        if num_envs is not None and num_envs != base.num_envs:
            raise ValueError(f"num_envs {num_envs} differs from the env's {base.num_envs}")
        self._env = env
        self.num_envs = base.num_envs
        self.auto_reset = auto_reset
        self.ignore_terminations = ignore_terminations
        self.record_metrics = record_metrics
        self.spec = env.spec
        self.single_observation_space = base.single_observation_space
        self.single_action_space = base.single_action_space
        self.observation_space = base.observation_space
        self.action_space = base.action_space
        self.metadata = dict(base.metadata, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
        self.render_mode = base.render_mode
        n = self.num_envs
        self._success_once = np.zeros(n, bool)
        self._returns = np.zeros(n, np.float32)

    @property
    def base_env(self) -> MjskillBatchedEnv:
        return self._env.unwrapped

    @property
    def unwrapped(self):
        return self.base_env

    @property
    def device(self):
        return self.base_env.device

    def _np(self, x: Any) -> np.ndarray:
        return np.asarray(_tensor_to_numpy(x, "values"))

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        obs, info = self._env.reset(seed=seed, options=options)
        if options is not None and options.get("env_idx") is not None:
            mask = self.base_env._index_mask(options["env_idx"])
        else:
            mask = np.ones(self.num_envs, bool)
        self._success_once[mask] = False
        self._returns[mask] = 0.0
        return obs, info

    def step(self, actions):
        obs, rew, terminated, truncated, info = self._env.step(actions)
        out = self.base_env._out
        term = self._np(terminated).copy()
        trunc = self._np(truncated)
        if self.record_metrics:
            self._returns += self._np(rew)
            self._success_once |= self._np(info["success"])
            length = self._np(self.base_env.elapsed_steps)
            episode = {
                "success_once": self._success_once.copy(),
                "return": self._returns.copy(),
                "episode_len": length.copy(),
                "reward": self._returns / np.maximum(length, 1),
            }
            if self.ignore_terminations:
                episode["success_at_end"] = self._np(info["success"]).copy()
            info["episode"] = out(episode)
        if self.ignore_terminations:
            term[:] = False
            terminated = out(term)
        done = term | trunc
        if self.auto_reset and done.any():
            final_obs, final_info = _copy(obs), _copy(info)
            obs, info = self.reset(options={"env_idx": np.flatnonzero(done)})
            info["final_observation"] = final_obs
            info["final_info"] = final_info
            mask = out(done)
            info["_final_info"] = mask
            info["_final_observation"] = mask
            info["_elapsed_steps"] = mask
        return obs, rew, terminated, truncated, info

    def close_extras(self, **kwargs: Any) -> None:
        self._env.close()

    def call(self, name: str, *args: Any, **kwargs: Any):
        attr = getattr(self.base_env, name)
        return attr(*args, **kwargs) if callable(attr) else attr

    def get_attr(self, name: str):
        return getattr(self.base_env, name)

    def render(self):
        return self.base_env.render()

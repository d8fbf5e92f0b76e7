"""Gymnasium classes over the native extension: :class:`MjskillEnv` (one env, a real
``gymnasium.Env``) and :class:`MjskillVectorEnv` (the Rust ``VecEnv``, a gymnasium 1.x
``VectorEnv`` with next-step autoreset)."""

from __future__ import annotations

import json
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _native
from ._common import (
    DEFAULT_QPOS_NOISE,
    DEFAULT_PINCH_SOLVER,
    DEFAULT_SIM_FREQ,
    DEPTH_DTYPES,
    MAX_SEED,
    OBS_MODES,
    RENDER_FPS,
    RENDER_MODES,
    _as_actions,
    _check_count,
    _check_depth_dtype,
    _check_render_mode,
    _check_seed,
    _describe,
    _merge_components,
    check_reconfiguration_freq,
    env_kwargs,
    live,
    reconfigure_option,
)

class MjskillEnv(gym.Env):
    """One mjskill env as a ``gymnasium.Env``, made with ManiSkill's keyword names.

    ``gym.make("mjskill/PickCube-v1", robot_uids="panda", obs_mode="state",
    control_mode="pd_ee_delta_pose", reward_mode="normalized_dense",
    render_mode="rgb_array", max_episode_steps=50)`` builds one. ``reset(seed=s)`` gives
    ManiSkill's exact initial state for seed ``s``. Made directly (not through ``gym.make``)
    the env truncates at ``max_episode_steps`` (default 50) itself; through ``gym.make``,
    gymnasium's ``TimeLimit`` wrapper truncates, as in ManiSkill.

    When MuJoCo raised instability warnings during a step (e.g. ``BadQacc``: the simulation
    diverged and MuJoCo reset it), ``info["warnings"]`` holds ``{kind: count}``, the Rust
    ``info.warnings``; the key is absent otherwise. One env may be used from several threads:
    the calls run one at a time (the GIL is released while a call waits for another).
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS}

    def __init__(
        self,
        env_id: str = "PickCube-v1",
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
        reconfiguration_freq: int | None = None,
    ):
        _check_render_mode(render_mode)
        _check_depth_dtype(depth_dtype)
        # Resolved here (ManiSkill's default for one env) and handed to the native env as such.
        reconfiguration_freq = check_reconfiguration_freq(reconfiguration_freq)
        self.reconfiguration_freq = reconfiguration_freq
        self._kwargs = dict(env_id=env_id, **env_kwargs(locals()))
        self._native = _native.Env(**self._kwargs)
        self.render_mode = render_mode
        self.action_space = _describe(self, self._native.spec(), depth_dtype)
        self.observation_space = self._layout.space

    # -- gymnasium API ---------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        seed = _check_seed(seed)
        reconfigure = bool(reconfigure_option(options).get("reconfigure", False))
        super().reset(seed=None if seed is None else seed % (MAX_SEED + 1))
        obs, info = self._native.reset(seed, reconfigure)
        return self._layout.single(obs, self._native), info

    def step(self, action):
        a = _as_actions(action, 1)
        obs, reward, terminated, truncated, info = self._native.step(a)
        return self._layout.single(obs, self._native), reward, terminated, truncated, info

    def render(self):
        """The human camera's frame (H×W×3 uint8) with ``render_mode="rgb_array"``."""
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; make the env with "
                'render_mode="rgb_array"'
            )
            return None
        return self._native.render()

    # -- ManiSkill-style state access ------------------------------------------------------
    def get_obs(self):
        """The observation of the current state (e.g. after ``set_state``)."""
        return self._layout.single(self._native.obs(), self._native)

    def get_info(self) -> dict:
        """The info of the current state."""
        return self._native.info()

    def get_state(self) -> dict:
        """Everything that determines the future (physics, controller targets, RNG
        streams), as a JSON-compatible dict; ``set_state`` restores it bitwise."""
        return json.loads(self._native.get_state())

    def set_state(self, state: dict) -> None:
        """Restores a state from ``get_state``; a bad state is a ``ValueError``."""
        if not isinstance(state, dict):
            raise TypeError(f"state must be a dict from get_state(), not {type(state).__name__}")
        _check_finite(state, "")
        self._native.set_state(json.dumps(state, default=_jsonable))

    def get_state_dict(self) -> dict:
        """ManiSkill's ``get_state_dict()`` layout (``actors``, ``articulations``,
        ``controller``) as nested lists, plus ``drive`` (the joints' drive targets, which
        ``set_state_dict`` restores; ManiSkill's own dicts lack it)."""
        return json.loads(self._native.get_state_dict())

    def set_state_dict(self, state_dict: dict) -> None:
        """ManiSkill's ``set_state_dict()``; numpy arrays are accepted as values."""
        if not isinstance(state_dict, dict):
            raise TypeError(f"state_dict must be a dict, not {type(state_dict).__name__}")
        _check_finite(state_dict, "")
        self._native.set_state_dict(json.dumps(state_dict, default=_jsonable))

    def expert_action(self) -> np.ndarray:
        """The state expert's action for the current state (issue 55's DAgger labels): a
        function of the state alone, so it can label any state a learner reaches, in this
        env's control mode (converted from the expert's own). Pairs: ``mjskill.STATE_EXPERTS``;
        any other is a ``ValueError`` naming the pair and those that have one."""
        return self._native.expert_action()

    def solver_action(self) -> np.ndarray:
        """The scripted solver's next action (``mjskill rollout --policy solver``) for the
        current state, in this env's control mode (converted from the solver's own). Unlike
        :meth:`expert_action` the solver keeps the plan it makes over an episode: it is built
        at the first call after each :meth:`reset` (and after unpickling) and then asked once
        per step. Between calls the state may come from elsewhere (:meth:`set_state_dict`), so
        it can run closed loop on another simulator's states
        (``examples/solver_in_maniskill.py``)."""
        return self._native.solver_action()

    @property
    def elapsed_steps(self) -> int:
        return self._native.elapsed_steps()

    # -- pickling (AsyncVectorEnv, Ray) ----------------------------------------------------
    def __reduce__(self):
        kwargs = dict(self._kwargs, depth_dtype=self.depth_dtype)
        return (_restore_env, (kwargs, self.render_mode, self._native.get_state()))


def _check_finite(value: Any, path: str) -> None:
    """JSON has no NaN or infinity: a non-finite number is named here (``physics[3] = inf
    is not finite``) instead of reaching the parser."""
    if isinstance(value, dict):
        for k, v in value.items():
            _check_finite(v, f"{path}.{k}" if path else str(k))
    elif isinstance(value, (list, tuple, np.ndarray)):
        try:
            arr = value if isinstance(value, np.ndarray) else np.asarray(value)
        except ValueError:  # ragged nesting
            arr = np.empty(len(value), dtype=object)
            arr[:] = list(value)
        if arr.dtype.kind == "f":
            bad = np.flatnonzero(~np.isfinite(arr.ravel()))
            if bad.size:
                i = int(bad[0])
                raise ValueError(
                    f"cannot set state: {path}[{i}] = {arr.ravel()[i]} is not finite"
                )
        elif arr.dtype == object:
            for i, v in enumerate(value):
                _check_finite(v, f"{path}[{i}]")
    elif isinstance(value, float) and not np.isfinite(value):
        raise ValueError(f"cannot set state: {path} = {value} is not finite")


def _jsonable(o: Any):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")


def _restore_env(kwargs: dict, render_mode: str | None, state: str) -> MjskillEnv:
    env = MjskillEnv(render_mode=render_mode, **kwargs)
    env._native.set_state(state)
    return env


#: The buffers of :meth:`MjskillVectorEnv.rollout`, in its argument order.
ROLLOUT_BUFFERS = ("obs", "actions", "rewards", "terminated", "truncated", "autoreset")


def rollout_buffers(envs: Any, steps: int, labels: bool = False) -> dict[str, np.ndarray]:
    """Zeroed rollout buffers of ``steps`` steps for ``envs`` (``num_envs`` and the single
    spaces): ``obs`` ``[T, N, obs_dim]`` and ``actions`` ``[T, N, act_dim]`` float32,
    ``rewards`` ``[T, N]`` float32, ``terminated``, ``truncated`` and ``autoreset`` ``[T, N]``
    bool; with ``labels``, also ``labels`` ``[T, N, act_dim]`` float32 for the state
    expert's labels."""
    t, n = int(steps), envs.num_envs
    od, ad = envs.single_observation_space.shape[0], envs.single_action_space.shape[0]
    out = dict(
        obs=np.zeros((t, n, od), np.float32),
        actions=np.zeros((t, n, ad), np.float32),
        rewards=np.zeros((t, n), np.float32),
        terminated=np.zeros((t, n), bool),
        truncated=np.zeros((t, n), bool),
        autoreset=np.zeros((t, n), bool),
    )
    if labels:
        out["labels"] = np.zeros((t, n, ad), np.float32)
    return out


class MjskillVectorEnv(VectorEnv):
    """N mjskill envs stepped on T threads in Rust, as a gymnasium 1.x ``VectorEnv``.

    ``gym.make_vec("mjskill/PickCube-v1", num_envs=N, vectorization_mode="vector_entry_point",
    num_threads=T)`` builds one. Autoreset is next-step (``metadata["autoreset_mode"]``): the
    step on which env i ends returns that episode's final observation, reward and info with
    ``terminated`` or ``truncated`` set; the next step ignores env i's action, resets it
    (unseeded, its random streams continue) and returns the new episode's first observation
    with reward 0. As in gymnasium's next-step mode there are no ``final_obs`` /
    ``final_info`` entries: the final observation is the one returned with the flag.
    ``reset(seed=s)`` seeds env i with ``s + i``, so results do not depend on T. The GIL is
    released while the envs step. ``num_envs`` and ``num_threads`` are in
    ``1..=mjskill._native.MAX_NUM_ENVS`` (16384). When some env raised MuJoCo warnings
    during a step, ``info["warnings"]`` is an object array of env i's ``{kind: count}`` dict
    (None for the others) with the mask ``info["_warnings"]``.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        env_id: str = "PickCube-v1",
        num_envs: int = 1,
        num_threads: int = 1,
        robot_uids: str | None = None,
        obs_mode: str = "state",
        control_mode: str | None = None,
        reward_mode: str = "normalized_dense",
        max_episode_steps: int | None = None,
        robot_init_qpos_noise: float = DEFAULT_QPOS_NOISE,
        sim_freq: int = DEFAULT_SIM_FREQ,
        pinch_solver: str = DEFAULT_PINCH_SOLVER,
        render_mode: str | None = None,
        depth_dtype: str = "float32",
        reconfiguration_freq: int | None = None,
    ):
        _check_depth_dtype(depth_dtype)
        if render_mode is not None:
            raise ValueError(
                f"render_mode {render_mode!r} is not supported by the vector env (it renders "
                "no human frames; its sensor images come with the visual obs modes); "
                "valid render modes: None"
            )
        num_envs = _check_count("num_envs", num_envs)
        num_threads = _check_count("num_threads", num_threads)
        reconfiguration_freq = check_reconfiguration_freq(reconfiguration_freq, num_envs)
        self.reconfiguration_freq = reconfiguration_freq
        self._kwargs = dict(env_id=env_id, **env_kwargs(locals()))
        # The static description (layout, bounds, cameras) comes from one plain env.
        spec = _native.Env(**self._kwargs).spec()
        self._native = _native.VecEnv(
            num_envs=int(num_envs), num_threads=int(num_threads), **self._kwargs
        )
        self.num_envs = int(num_envs)
        self.num_threads = self._native.num_threads
        self.render_mode = None
        self.max_episode_steps = spec["max_episode_steps"]
        self.single_action_space = _describe(self, spec, depth_dtype)
        self.single_observation_space = self._layout.space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        if isinstance(seed, (list, tuple)):
            seeds = [_check_seed(s) for s in seed]
            if len(seeds) != self.num_envs or any(
                s != seeds[0] + i for i, s in enumerate(seeds)
            ):
                raise ValueError(
                    f"seed list {list(seed)} is not supported: env i is seeded with s + i, so "
                    f"give one int s or the list [s, s+1, ..., s+{self.num_envs - 1}]"
                )
            seed = seeds[0]
        seed = _check_seed(seed)
        reconfigure = bool(reconfigure_option(options).get("reconfigure", False))
        native = self._live()
        if seed is not None:
            self._np_random, self._np_random_seed = gym.utils.seeding.np_random(seed)
        obs, info = native.reset(seed, reconfigure)
        return self._layout.batch(obs, native), _merge_components(info)

    def step(self, actions):
        native = self._live()
        a = _as_actions(actions, 2)
        obs, rewards, terminated, truncated, info = native.step(a)
        return (
            self._layout.batch(obs, native),
            rewards,
            terminated,
            truncated,
            _merge_components(info),
        )

    @property
    def autoreset(self) -> np.ndarray:
        """Envs that reset during the last step (their action was ignored)."""
        return self._live().autoreset()

    def close_extras(self, **kwargs: Any) -> None:
        """Frees the N envs and their threads (``close()`` calls it once; each env owns its
        MuJoCo model and data). ``reset``, ``step`` and ``rollout`` after it raise
        ``RuntimeError``."""
        self._native = None

    def _live(self) -> Any:
        """The native envs, or a ``RuntimeError`` once the env is closed."""
        return live(self._native, f"this mjskill/{self._kwargs['env_id']} vector env "
                                   f"(num_envs={self.num_envs})")

    def rollout_buffers(self, steps: int, labels: bool = False) -> dict[str, np.ndarray]:
        """Buffers for :meth:`rollout` of ``steps`` steps: ``obs`` ``[T, N, obs_dim]`` and
        ``actions`` ``[T, N, act_dim]`` float32, ``rewards`` ``[T, N]`` float32,
        ``terminated``, ``truncated`` and ``autoreset`` ``[T, N]`` bool; with ``labels``, also
        ``labels`` ``[T, N, act_dim]`` float32, which :meth:`rollout` fills with the state
        expert's actions (DAgger)."""
        if self._layout.dict_obs:
            raise ValueError(
                f"rollout takes flat observations (obs_mode 'state'), not {self._layout.obs_mode!r}"
            )
        return rollout_buffers(self, steps, labels)

    def expert_actions(self) -> np.ndarray:
        """Every env's state-expert action for its current state, ``[N, act_dim]`` float32
        (the single env's :meth:`MjskillEnv.expert_action`, computed on the env threads). A
        pair without a state expert (``mjskill.STATE_EXPERTS``) is a ``ValueError``."""
        return self._live().expert_actions()

    def rollout(self, policy, first_step: int, buffers: dict[str, np.ndarray]) -> np.ndarray:
        """Runs T steps (the buffers' length, :meth:`rollout_buffers`) in one call, with
        ``policy`` (a :class:`mjskill.GaussianMlp`) evaluated on the env threads: before each
        step, env i's raw action is the policy's for its current observation, and the env
        steps with it clipped to the action space (or autoresets, as :meth:`step` does).
        Step t is the policy's step ``first_step + t`` (the key of its sampling noise, with
        the env's index). The buffers receive each step's observation before the step, raw
        action (0 where the env reset instead), reward and flags, and, when the buffers have
        ``labels`` (``rollout_buffers(T, labels=True)``), the state expert's action for the
        state each action was chosen from (0 where the env reset): a DAgger round's learner
        steps and expert labels in one call. Returns the observations after the last step.
        The results do not depend on ``num_threads``.

        The buffers must be as :meth:`rollout_buffers` makes them: exactly its dtypes and
        shapes, C-contiguous, writable and each in its own memory; ``first_step + T`` is at
        most 2**48. Anything else is a ``TypeError`` or ``ValueError`` naming the buffer, with
        nothing stepped (docs/limits.md)."""
        if self._layout.dict_obs:
            raise ValueError(
                f"rollout takes flat observations (obs_mode 'state'), not {self._layout.obs_mode!r}"
            )
        native = self._live()
        if not isinstance(buffers, dict):
            raise TypeError(
                f"buffers must be the dict rollout_buffers(T) returns, not {type(buffers).__name__}"
            )
        missing = [k for k in ROLLOUT_BUFFERS if k not in buffers]
        if missing:
            raise ValueError(
                f"buffers lack {', '.join(missing)}; rollout takes the dict rollout_buffers(T) "
                f"returns (keys {', '.join(ROLLOUT_BUFFERS)})"
            )
        b = buffers
        _, obs = _native.rollout(native, policy, first_step, b["obs"], b["actions"],
                                 b["rewards"], b["terminated"], b["truncated"], b["autoreset"],
                                 b.get("labels"))
        return obs


def __getattr__(name: str) -> Any:
    # make_env and make_vector_env moved to mjskill.entry_points (envs.py no longer imports
    # the batched env); the old names stay as deprecated aliases.
    if name in ("make_env", "make_vector_env"):
        from . import entry_points

        warnings.warn(
            f"mjskill.envs.{name} is deprecated: use mjskill.{name} "
            f"(mjskill.entry_points.{name})",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(entry_points, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

"""Gymnasium classes over the native extension: :class:`MjskillEnv` (one env, a real
``gymnasium.Env``) and :class:`MjskillVectorEnv` (the Rust ``VecEnv``, a gymnasium 1.x
``VectorEnv`` with next-step autoreset)."""

from __future__ import annotations

import json
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _native

MAX_SEED = 2**32 - 1
"""ManiSkill's seeds are 32-bit."""

RENDER_MODES = ["rgb_array"]
OBS_MODES = [
    "state",
    "state_dict",
    "none",
    "rgb",
    "depth",
    "rgbd",
    "segmentation",
    "rgb+segmentation",
    "depth+segmentation",
    "rgb+depth+segmentation",
    "pointcloud",
]
"""ManiSkill's obs modes; any ``+`` combination of rgb, depth and segmentation is accepted."""
DEPTH_DTYPES = ["float32", "int16"]
"""Depth images: float32 metres, or ManiSkill's int16 millimetres."""
_UNLIMITED = 2**32 - 1
"""Rust-side episode length of envs made by ``gym.make``: its ``TimeLimit`` truncates."""


def _check_seed(seed: Any) -> int | None:
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be an int or None, not {type(seed).__name__} ({seed!r})")
    seed = int(seed)
    if not 0 <= seed <= MAX_SEED:
        raise ValueError(f"seed {seed} is out of range: seeds are 32-bit, 0..={MAX_SEED}")
    return seed


def _check_render_mode(render_mode: Any) -> None:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(
            f"unknown render_mode {render_mode!r}; valid render modes: "
            f"{', '.join(RENDER_MODES)} (or None)"
        )


_F32_MAX = float(np.finfo(np.float32).max)


def _as_actions(action: Any, ndim: int) -> np.ndarray:
    """``action`` as a C-contiguous float32 array of ``ndim`` dimensions (no copy when it
    already is one); a non-numeric or boolean action is a ``TypeError``, a wrong rank a ``ValueError``,
    and a finite value beyond float32's range (which the cast would turn into infinity) a
    ``ValueError`` naming the value given."""
    a = action if isinstance(action, np.ndarray) else np.asarray(action)
    if a.dtype.kind not in "iuf":
        # Booleans too: True/False are not joint targets, and taking them as 1/0 would hide
        # a mask passed where actions belong.
        raise TypeError(
            f"actions must be numeric: floats or ints (float32 preferred), got dtype {a.dtype} from "
            f"{type(action).__name__}"
        )
    if a.ndim != ndim:
        want = "(action_dim,)" if ndim == 1 else "(num_envs, action_dim)"
        raise ValueError(f"actions have shape {a.shape}, expected {want}")
    if a.dtype.kind == "f" and a.dtype.itemsize > 4:
        with np.errstate(invalid="ignore"):
            big = np.isfinite(a) & (np.abs(a) > _F32_MAX)
        if big.any():
            at = tuple(int(i) for i in np.argwhere(big)[0])
            name = f"action[{at[0]}]" if ndim == 1 else f"actions[{at[0]}, {at[1]}]"
            raise ValueError(
                f"{name} = {float(a[at])!r} is outside the float32 range (|value| <= {_F32_MAX:.9g}); "
                "actions are float32"
            )
    if a.dtype != np.float32 or not a.flags.c_contiguous:
        a = np.ascontiguousarray(a, dtype=np.float32)
    return a


def _nest(flat: dict[str, Any]) -> dict[str, Any]:
    """``{"agent/qpos": x}`` → ``{"agent": {"qpos": x}}``."""
    out: dict[str, Any] = {}
    for key, value in flat.items():
        node = out
        parts = key.split("/")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return out


def _to_space(tree: Any) -> spaces.Space:
    if isinstance(tree, dict):
        return spaces.Dict({k: _to_space(v) for k, v in tree.items()})
    return tree


def _check_depth_dtype(depth_dtype: Any) -> None:
    if depth_dtype not in DEPTH_DTYPES:
        raise ValueError(
            f"unknown depth_dtype {depth_dtype!r}; valid: {', '.join(DEPTH_DTYPES)} (float32: "
            "metres; int16: ManiSkill's millimetres, 0 where nothing was seen)"
        )


def _gripper_qvel_obs(spec: dict[str, Any]) -> tuple[int, ...]:
    """Indices into the flat state observation of the gripper joints' ``agent/qvel`` entries
    (empty when the observation has no ``agent/qvel``)."""
    start = next((a for name, a, _ in spec["obs_layout"] if name == "agent/qvel"), None)
    if start is None or spec["obs_mode"] not in ("state", "state_dict"):
        return ()
    return tuple(start + k for k in spec["gripper_joints"])


def _check_count(name: str, v: Any) -> None:
    """``num_envs`` or ``num_threads``: an int in 1..=MAX_NUM_ENVS."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name} must be an int, not {type(v).__name__} ({v!r})")
    if not 1 <= v <= _native.MAX_NUM_ENVS:
        raise ValueError(
            f"{name} {v} is out of range: 1..={_native.MAX_NUM_ENVS} (each env owns its MuJoCo "
            "model and data; more threads than envs are clamped)"
        )


def _describe(env: Any, spec: dict[str, Any], depth_dtype: str) -> spaces.Box:
    """Sets what every mjskill env class tells about itself from the native ``spec`` (ids,
    modes, segmentation ids, observation layout, the gripper velocities' indices) and returns
    the action space of one env."""
    env.env_id = spec["env_id"]
    env.robot_uids = spec["robot_uids"]
    env.control_mode = spec["control_mode"]
    env.obs_mode = spec["obs_mode"]
    env.reward_mode = spec["reward_mode"]
    env.depth_dtype = depth_dtype
    env.segmentation_id_map = dict(spec["segmentation_id_map"])
    env._layout = _Layout(spec, depth_dtype)
    #: Flat-state indices of the gripper joints' velocities (``agent/qvel``), which PhysX
    #: reports as a solver residual while a gripper pinches (docs/outcome-physics.md).
    env.gripper_qvel_obs = _gripper_qvel_obs(spec)
    lo, hi = spec["action_low"], spec["action_high"]
    return spaces.Box(lo, hi, shape=lo.shape, dtype=np.float32)


class _Layout:
    """How a flat observation (plus sensor images) becomes the observation of an obs mode."""

    def __init__(self, spec: dict[str, Any], depth_dtype: str = "float32"):
        self.obs_mode = spec["obs_mode"]
        self.parts = [(name, a, b) for name, a, b in spec["obs_layout"]]
        self.cameras = spec["cameras"]
        self.points = spec["point_count"]
        self.depth_mm = depth_dtype == "int16"
        ids = [i for i, _ in spec["segmentation_id_map"]]
        max_id = max(ids, default=0)
        low, high = spec["obs_low"], spec["obs_high"]
        self.dict_obs = self.obs_mode not in ("state", "none")
        if not self.dict_obs:
            self.space: spaces.Space = spaces.Box(low, high, shape=low.shape, dtype=np.float32)
            return
        flat = {
            name: spaces.Box(low[a:b], high[a:b], shape=(b - a,), dtype=np.float32)
            for name, a, b in self.parts
        }
        for cam, w, h, rgb, depth, seg in self.cameras:
            if rgb:
                flat[f"sensor_data/{cam}/rgb"] = spaces.Box(0, 255, (h, w, 3), np.uint8)
            if depth and self.depth_mm:
                flat[f"sensor_data/{cam}/depth"] = spaces.Box(0, 32767, (h, w, 1), np.int16)
            elif depth:
                flat[f"sensor_data/{cam}/depth"] = spaces.Box(
                    0.0, np.inf, (h, w, 1), np.float32
                )
            if seg:
                flat[f"sensor_data/{cam}/segmentation"] = spaces.Box(
                    0, max_id, (h, w, 1), np.int16
                )
        if self.points is not None:
            n = self.points
            flat["pointcloud/xyzw"] = spaces.Box(-np.inf, np.inf, (n, 4), np.float32)
            flat["pointcloud/rgb"] = spaces.Box(0, 255, (n, 3), np.uint8)
            flat["pointcloud/segmentation"] = spaces.Box(0, max_id, (n, 1), np.int16)
        self.space = _to_space(_nest(flat))

    def _visual(self, out: dict[str, Any], native: Any) -> dict[str, Any]:
        if self.cameras:
            out["sensor_data"] = native.images(self.depth_mm)
        if self.points is not None:
            out["pointcloud"] = native.point_cloud()
        return out

    def single(self, obs: np.ndarray, native: Any) -> Any:
        if not self.dict_obs:
            return obs
        return self._visual(_nest({name: obs[a:b] for name, a, b in self.parts}), native)

    def batch(self, obs: np.ndarray, native: Any) -> Any:
        if not self.dict_obs:
            return obs
        return self._visual(_nest({name: obs[:, a:b] for name, a, b in self.parts}), native)


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

    metadata = {"render_modes": RENDER_MODES, "render_fps": 20}

    def __init__(
        self,
        env_id: str = "PickCube-v1",
        robot_uids: str | None = None,
        obs_mode: str = "state",
        control_mode: str | None = None,
        reward_mode: str = "normalized_dense",
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
        robot_init_qpos_noise: float = 0.02,
        sim_freq: int = 100,
        depth_dtype: str = "float32",
    ):
        _check_render_mode(render_mode)
        _check_depth_dtype(depth_dtype)
        self._kwargs = dict(
            env_id=env_id,
            robot_uids=robot_uids,
            obs_mode=obs_mode,
            control_mode=control_mode,
            reward_mode=reward_mode,
            max_episode_steps=max_episode_steps,
            robot_init_qpos_noise=robot_init_qpos_noise,
            sim_freq=sim_freq,
        )
        self._native = _native.Env(**self._kwargs)
        self.render_mode = render_mode
        self.action_space = _describe(self, self._native.spec(), depth_dtype)
        self.observation_space = self._layout.space

    # -- gymnasium API ---------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        seed = _check_seed(seed)
        if options:
            raise ValueError(
                f"unsupported reset options {sorted(options)}; mjskill envs take no options"
            )
        super().reset(seed=None if seed is None else seed % (MAX_SEED + 1))
        obs, info = self._native.reset(seed)
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
        robot_init_qpos_noise: float = 0.02,
        sim_freq: int = 100,
        render_mode: str | None = None,
        depth_dtype: str = "float32",
    ):
        _check_depth_dtype(depth_dtype)
        if render_mode is not None:
            raise ValueError(
                f"render_mode {render_mode!r} is not supported by the vector env (it renders "
                "no human frames; its sensor images come with the visual obs modes); "
                "valid render modes: None"
            )
        _check_count("num_envs", num_envs)
        _check_count("num_threads", num_threads)
        self._kwargs = dict(
            env_id=env_id,
            robot_uids=robot_uids,
            obs_mode=obs_mode,
            control_mode=control_mode,
            reward_mode=reward_mode,
            max_episode_steps=max_episode_steps,
            robot_init_qpos_noise=robot_init_qpos_noise,
            sim_freq=sim_freq,
        )
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
        if options:
            raise ValueError(
                f"unsupported reset options {sorted(options)}; mjskill envs take no options"
            )
        if seed is not None:
            self._np_random, self._np_random_seed = gym.utils.seeding.np_random(seed)
        obs, info = self._native.reset(seed)
        return self._layout.batch(obs, self._native), info

    def step(self, actions):
        a = _as_actions(actions, 2)
        obs, rewards, terminated, truncated, info = self._native.step(a)
        return self._layout.batch(obs, self._native), rewards, terminated, truncated, info

    @property
    def autoreset(self) -> np.ndarray:
        """Envs that reset during the last step (their action was ignored)."""
        return self._native.autoreset()

def make_env(num_envs: int = 1, **kwargs):
    """``gym.make`` entry point.

    ``num_envs=1`` (the default): one :class:`MjskillEnv` in gymnasium's
    ``PassiveEnvChecker`` (the ids are registered with the checker off, for the batched env);
    its own episode limit is lifted, because gymnasium's ``TimeLimit`` (``max_episode_steps``,
    default 50) truncates, as in ManiSkill. ``num_envs > 1`` (ManiSkill's ``gym.make(...,
    num_envs=N)``): the batched :class:`mjskill.batched.MjskillBatchedEnv`, which truncates
    each env itself (it disarms gymnasium's ``TimeLimit``). ManiSkill's ``sim_backend`` and
    ``reconfiguration_freq`` keywords are accepted and checked (mjskill simulates with MuJoCo
    on the CPU; its scenes have nothing to reconfigure).
    """
    from .batched import MjskillBatchedEnv, check_reconfiguration_freq, check_sim_backend

    _check_count("num_envs", num_envs)
    if num_envs > 1:
        return MjskillBatchedEnv(num_envs=int(num_envs), **kwargs)
    check_sim_backend(kwargs.pop("sim_backend", "auto"))
    check_reconfiguration_freq(kwargs.pop("reconfiguration_freq", None))
    batched_only = sorted({"num_threads", "array_backend"} & set(kwargs))
    if batched_only:
        env_id = kwargs.get("env_id", "PickCube-v1")
        raise ValueError(
            f"{', '.join(batched_only)} apply to the batched env (num_envs > 1); "
            f"gym.make('mjskill/{env_id}', num_envs=1) is one MjskillEnv (numpy values)"
        )
    kwargs.setdefault("max_episode_steps", _UNLIMITED)
    return gym.wrappers.PassiveEnvChecker(MjskillEnv(**kwargs))


def make_vector_env(**kwargs) -> MjskillVectorEnv:
    """``gym.make_vec(..., vectorization_mode="vector_entry_point")`` entry point."""
    return MjskillVectorEnv(**kwargs)

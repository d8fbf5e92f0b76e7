"""What every mjskill env class shares: the env contract read from the native module
(:data:`ENV_KWARGS` and the defaults, seed and count checks, limits), action conversion and
the observation layout. :mod:`mjskill.envs` and :mod:`mjskill.batched` both build on it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from . import _native

MAX_SEED: int = _native.MAX_SEED
"""ManiSkill's seeds are 32-bit: ``0..=MAX_SEED``."""

ENV_KWARGS: dict[str, Any] = dict(_native.ENV_KWARGS)
"""ManiSkill's env keyword arguments with their defaults, as the native classes declare them
(every mjskill env class takes them)."""
DEFAULT_QPOS_NOISE: float = ENV_KWARGS["robot_init_qpos_noise"]
"""Std-dev of the initial joint noise (ManiSkill's ``robot_init_qpos_noise``)."""
DEFAULT_SIM_FREQ: int = ENV_KWARGS["sim_freq"]
#: Who takes the physics steps in which a gripper pinches the object: ``"mujoco"`` (the
#: default) or ``"physx_tgs"`` (a replica of PhysX's step; so100; docs/physics.md).
DEFAULT_PINCH_SOLVER: str = ENV_KWARGS["pinch_solver"]
"""Physics steps per second."""
RENDER_FPS: int = _native.CONTROL_FREQ
"""Frames per second of rendered episodes: one per control step."""
UNLIMITED: int = _native.UNLIMITED_EPISODE_STEPS
"""Native episode length without a time limit (for envs whose limit is applied outside)."""

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


def _check_seed(seed: Any, name: str = "seed") -> int | None:
    """``None`` or a seed in ``0..=MAX_SEED`` (the native check: a ``ValueError`` naming the
    seed and the range, a ``TypeError`` for anything but an int)."""
    return _native.check_seed(seed, name)


def env_kwargs(values: dict[str, Any]) -> dict[str, Any]:
    """The :data:`ENV_KWARGS` entries of ``values`` (a constructor's ``locals()``), which the
    native classes take."""
    return {k: values[k] for k in ENV_KWARGS}


def _check_render_mode(render_mode: Any) -> None:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(
            f"unknown render_mode {render_mode!r}; valid render modes: "
            f"{', '.join(RENDER_MODES)} (or None)"
        )


_F32_MAX = float(np.finfo(np.float32).max)


def _tensor_to_numpy(x: Any, what: str) -> Any:
    """A torch tensor (anything with ``detach``) as a numpy array on the CPU; other values
    unchanged. Torch floats numpy has no dtype for (``bfloat16``) become float32, and another
    dtype numpy cannot hold is a ``TypeError`` naming ``what`` and the dtype."""
    if not hasattr(x, "detach"):
        return x
    t = x.detach().cpu()
    if t.is_floating_point() and str(t.dtype) not in ("torch.float16", "torch.float32",
                                                       "torch.float64"):
        t = t.float()
    try:
        return t.numpy()
    except (TypeError, RuntimeError) as e:
        raise TypeError(
            f"{what} have torch dtype {t.dtype}, which numpy cannot hold; give float32 "
            f"({what}.float()) or int values"
        ) from e


def _as_actions(action: Any, ndim: int) -> np.ndarray:
    """``action`` as a C-contiguous float32 array of ``ndim`` dimensions (no copy when it
    already is one); a non-numeric or boolean action is a ``TypeError``, a wrong rank a ``ValueError``,
    and a finite value beyond float32's range (which the cast would turn into infinity) a
    ``ValueError`` naming the value given."""
    action = _tensor_to_numpy(action, "actions")
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


def _merge_components(info: dict[str, Any]) -> dict[str, Any]:
    """One array per vector info value of a batch of envs.

    The native vector envs give a vector value one key per component, ``name[0]``,
    ``name[1]``, ... (PegInsertionSide-v1's ``peg_head_pos_at_hole``), each an array over the
    envs. They become one ``name`` array of shape ``[N, k]``, as ManiSkill's, and their gymnasium
    masks ``_name[i]`` the one mask ``_name`` (an env is set where every component is). In
    place; returns ``info``.
    """
    parts: dict[str, list[tuple[int, Any]]] = {}
    for key in [k for k in info if k.endswith("]") and "[" in k]:
        name, index = key[:-1].rsplit("[", 1)
        parts.setdefault(name, []).append((int(index), info.pop(key)))
    for name, values in parts.items():
        stacked = np.stack([v for _, v in sorted(values, key=lambda p: p[0])], axis=-1)
        info[name] = np.logical_and.reduce(stacked, axis=-1) if name.startswith("_") else stacked
    return info


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


def _check_count(name: str, v: Any) -> int:
    """``num_envs`` or ``num_threads``: an int in 1..=MAX_NUM_ENVS (the native check)."""
    return _native.check_count(v, name)


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


SIM_BACKENDS = ["auto", "cpu", "gpu", "physx_cpu", "physx_cuda", "cuda"]
"""ManiSkill's ``sim_backend`` values, accepted so that ManiSkill scripts run unchanged; mjskill
simulates with MuJoCo on CPU threads whichever is given."""


def check_sim_backend(sim_backend: Any) -> None:
    if sim_backend not in SIM_BACKENDS:
        raise ValueError(
            f"unknown sim_backend {sim_backend!r}; valid: {', '.join(SIM_BACKENDS)} (ManiSkill's "
            "names; mjskill always simulates with MuJoCo on CPU threads)"
        )


def check_reconfiguration_freq(freq: Any, num_envs: int = 1) -> int:
    """ManiSkill's ``reconfiguration_freq``, resolved: every how many resets a task whose
    shapes are drawn per episode (PegInsertionSide-v1) draws them anew; 0: only when the env
    is made (env i of a batch from seed 2022 + i) and on ``reset(options={"reconfigure":
    True})``. None is ManiSkill's default: 1 for one env, 0 for ``num_envs > 1``. The other
    tasks' scenes are fixed: nothing to redraw."""
    if freq is None:
        return 1 if num_envs == 1 else 0
    if isinstance(freq, bool) or not isinstance(freq, (int, np.integer)) or freq < 0:
        raise ValueError(
            f"reconfiguration_freq must be None or an int >= 0, got {freq!r} (resets between "
            "redraws of PegInsertionSide-v1's shapes; None: 1 for one env, 0 for a batch)"
        )
    return int(freq)


def reconfigure_option(options: Any, valid: tuple[str, ...] = ("reconfigure",)) -> dict:
    """The reset ``options`` as a dict (None: empty) whose keys are all in ``valid`` and whose
    ``reconfigure``, if given, is a bool; a ``TypeError`` or ``ValueError`` names the bad
    value and the valid choices."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(
            f"options must be a dict such as {{'reconfigure': True}} (or None), got "
            f"{type(options).__name__}"
        )
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ValueError(f"unsupported reset options {unknown}; valid: {', '.join(valid)}")
    r = options.get("reconfigure", False)
    if not isinstance(r, (bool, np.bool_)):
        raise TypeError(f"options['reconfigure'] must be a bool, got {r!r}")
    return dict(options)


def live(native: Any, what: str, remedy: str = "make a new one") -> Any:
    """``native`` (the native envs of a vector env), or a ``RuntimeError`` naming ``what``
    and the ``remedy`` once it is closed (``native`` is None)."""
    if native is None:
        raise RuntimeError(f"{what} is closed; {remedy}")
    return native

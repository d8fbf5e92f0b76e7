"""Policy files in Python: :class:`OnnxPolicy` runs one with ``onnxruntime`` (the optional
extra ``mjskill[onnx]``), the same file ``mjskill eval --policy`` and ``mjskill rollout
--policy`` run in Rust (docs/training.md).

A policy file is an ONNX graph, observation in (``[batch, obs_dim]`` float32, any
normalisation inside the graph), mean action out (``[batch, act_dim]``), whose
``metadata_props`` name the env, robot, control mode and observation mode it was trained on
and the command that trained it::

    policy = OnnxPolicy("pickcube.onnx")
    env = policy.make_env()                      # gym.make with the file's env and modes
    obs, _ = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(policy(obs))
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np

#: The metadata_props every policy file carries.
METADATA_KEYS = ("env_id", "robot_uids", "control_mode", "obs_mode", "training_command")
_STATE_MODES = ("state", "state_dict")


def _space_of(env: Any) -> tuple[gym.spaces.Box, gym.spaces.Space, Any]:
    """(single action space, single observation space, the unwrapped env) of an env, a vector
    env or a batched env (``gym.make(..., num_envs=N)``, whose wrappers do not forward
    ``single_action_space``)."""
    base = getattr(env, "unwrapped", env)
    for e in (env, base):
        if hasattr(e, "single_action_space"):
            return e.single_action_space, e.single_observation_space, base
    return env.action_space, env.observation_space, base


class OnnxPolicy:
    """A policy file run with onnxruntime: ``policy(obs)`` gives the mean action (float32),
    clipped to the action space's bounds, for one observation ``[obs_dim]`` or a batch
    ``[n, obs_dim]``.

    ``env`` (an mjskill env or vector env) is checked against the file: its env id, robot,
    control mode and obs mode must be the metadata's, and the graph must take its observation
    size and give its action size. Without ``env`` the file is checked against a fresh
    :class:`~mjskill.MjskillEnv` made from its metadata. Errors name the file and both values.
    """

    def __init__(self, path: str | os.PathLike, env: Any = None):
        try:
            import onnxruntime as ort
        except ImportError as e:
            raise ImportError(
                "OnnxPolicy needs onnxruntime: pip install onnxruntime (or mjskill[onnx])"
            ) from e
        self.path = os.fspath(path)
        if not os.path.exists(self.path):
            raise FileNotFoundError(f"cannot read policy file {self.path}: no such file")
        from . import _native

        # The file is checked by mjskill's own rules first (the same code as `mjskill eval
        # --policy`: regular file, size limits, metadata, graph interface, a run on zeros), so
        # that both languages accept and refuse the same files; errors are ValueErrors naming
        # the file.
        props = _native.check_policy_file(self.path)
        self.metadata: dict[str, str] = dict(props)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        opts.inter_op_num_threads = 1
        opts.log_severity_level = 3
        try:
            self._session = ort.InferenceSession(
                self.path, sess_options=opts, providers=["CPUExecutionProvider"]
            )
            inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        except Exception as e:  # onnxruntime raises its own exception types
            raise ValueError(f"policy file {self.path} is not a valid ONNX model: {e}") from e
        if len(inputs) != 1 or len(outputs) != 1:
            raise ValueError(
                f"policy file {self.path}: the graph has {len(inputs)} inputs and "
                f"{len(outputs)} outputs; a policy file has one input (the observation) and "
                "one output (the action)"
            )
        self._input = inputs[0].name
        self._input_rank = len(inputs[0].shape)
        if env is None:
            from .envs import MjskillEnv

            env = MjskillEnv(**self.env_kwargs())
        self._check(env)

    # -- metadata --------------------------------------------------------------------------
    @property
    def env_id(self) -> str:
        return self.metadata["env_id"]

    @property
    def robot_uids(self) -> str:
        return self.metadata["robot_uids"]

    @property
    def control_mode(self) -> str:
        return self.metadata["control_mode"]

    @property
    def obs_mode(self) -> str:
        return self.metadata["obs_mode"]

    @property
    def training_command(self) -> str:
        return self.metadata["training_command"]

    def env_kwargs(self, **overrides: Any) -> dict:
        """The env's keywords (env_id, robot_uids, control_mode, obs_mode) from the metadata,
        with ``overrides`` (checked: a value that differs from the file's is a ValueError)."""
        kw = {
            "env_id": self.env_id,
            "robot_uids": self.robot_uids,
            "control_mode": self.control_mode,
            "obs_mode": "state",
        }
        for k, v in overrides.items():
            if k in ("env_id", "robot_uids", "control_mode") and v is not None and v != kw[k]:
                raise ValueError(
                    f"policy file {self.path} was trained with {k} {kw[k]!r}, but {v!r} was "
                    "requested; leave the keyword out to use the file's"
                )
            if k == "obs_mode" and v not in _STATE_MODES:
                raise ValueError(
                    f"policy file {self.path} was trained with obs_mode {self.obs_mode!r}, but "
                    f"{v!r} was requested"
                )
        kw.update({k: v for k, v in overrides.items() if v is not None})
        return kw

    def make_env(self, **kwargs: Any) -> gym.Env:
        """``gym.make`` of the file's env with its robot and modes (plus ``kwargs``)."""
        kw = self.env_kwargs(**kwargs)
        return gym.make(f"mjskill/{kw.pop('env_id')}", **kw)

    def make_vec(self, num_envs: int, **kwargs: Any):
        """``gym.make_vec`` (the native vector env) of the file's env with its robot and modes."""
        kw = self.env_kwargs(**kwargs)
        return gym.make_vec(f"mjskill/{kw.pop('env_id')}", num_envs=num_envs, **kw)

    # -- running ---------------------------------------------------------------------------
    def _check(self, env: Any) -> None:
        act_space, obs_space, base = _space_of(env)
        for key, attr in (
            ("env_id", "env_id"),
            ("robot_uids", "robot_uids"),
            ("control_mode", "control_mode"),
        ):
            have = getattr(base, attr, None)
            if have is not None and have != self.metadata[key]:
                raise ValueError(
                    f"policy file {self.path} was trained with {key} {self.metadata[key]!r}, "
                    f"but the env has {have!r}"
                )
        obs_mode = getattr(base, "obs_mode", "state")
        if obs_mode not in _STATE_MODES:
            raise ValueError(
                f"policy file {self.path} was trained with obs_mode {self.obs_mode!r}, but the "
                f"env has {obs_mode!r}"
            )
        obs_dim = int(np.prod(obs_space.shape)) if obs_space.shape else None
        if obs_dim is None:  # state_dict: the flat vector's size is the parts' total
            obs_dim = sum(int(np.prod(s.shape)) for s in _leaves(obs_space))
        self.obs_dim = obs_dim
        self.act_dim = int(np.prod(act_space.shape))
        self.low = np.asarray(act_space.low, np.float32).reshape(-1)
        self.high = np.asarray(act_space.high, np.float32).reshape(-1)
        shape = self._session.get_inputs()[0].shape
        declared = shape[-1] if shape else None
        if isinstance(declared, int) and declared != obs_dim:
            raise ValueError(
                f"policy file {self.path} takes observations of {declared} values, but "
                f"{self.metadata['env_id']} gives {obs_dim} (obs_mode {obs_mode})"
            )
        try:
            out = self._run(np.zeros((1, obs_dim), np.float32))
        except Exception as e:  # onnxruntime's own exception types
            raise ValueError(f"policy file {self.path} failed to run: {e}") from e
        if out.shape[-1] != self.act_dim:
            raise ValueError(
                f"policy file {self.path} outputs actions of {out.shape[-1]} values, but "
                f"{self.robot_uids} in control mode {self.control_mode} takes {self.act_dim}"
            )

    def _run(self, obs: np.ndarray) -> np.ndarray:
        x = obs if self._input_rank == 2 else obs.reshape(-1)
        (out,) = self._session.run(None, {self._input: x})
        return np.asarray(out, np.float32).reshape(obs.shape[0], -1)

    def __call__(self, obs: Any) -> np.ndarray:
        """The clipped mean action for ``obs`` (``[obs_dim]`` → ``[act_dim]``, ``[n, obs_dim]``
        → ``[n, act_dim]``)."""
        o = np.asarray(obs, dtype=np.float32)
        single = o.ndim == 1
        batch = o.reshape(1, -1) if single else o
        if batch.ndim != 2 or batch.shape[1] != self.obs_dim:
            raise ValueError(
                f"observations have shape {o.shape}; policy file {self.path} takes "
                f"({self.obs_dim},) or (n, {self.obs_dim})"
            )
        if self._input_rank == 2:
            out = self._run(np.ascontiguousarray(batch))
        else:
            out = np.stack([self._run(row[None])[0] for row in batch])
        a = np.clip(out, self.low, self.high)
        return a[0] if single else a


def _leaves(space: gym.spaces.Space):
    if isinstance(space, gym.spaces.Dict):
        for s in space.spaces.values():
            yield from _leaves(s)
    elif not (len(space.shape) == 3):  # camera images are not part of the state vector
        yield space

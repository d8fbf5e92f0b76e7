"""Recorded rollouts sharded by seed range across Ray workers (``pip install mjskill[ray]``).

:func:`rollout` splits a seed range into one contiguous shard per worker. Each worker runs a
native :class:`~mjskill.MjskillVectorEnv` over its seeds (episode ``s`` is the env reset with
seed ``s``, run until it terminates or truncates) and writes its episodes to
``<out_dir>/shard-<first seed>-<last seed>.mcap``; ``mjskill info <out_dir>`` reads the
directory as one dataset. The merged statistics equal those of one process doing all seeds
(``use_ray=False`` runs exactly that), because every episode depends only on its seed and
policy: the built-in ``"random"`` policy draws episode ``s``'s actions from
``numpy.random.default_rng(s)``, and a callable policy maps each observation row to an
action row.

:class:`RayVectorEnv` is for training: one vector env of ``num_envs`` envs whose contiguous
shares step on Ray actors, each a native :class:`~mjskill.MjskillVectorEnv`, with PPO's actor
evaluated on the actors' threads (:meth:`RayVectorEnv.rollout`). Env ``i`` is seeded and
sampled as env ``i`` of one :class:`~mjskill.MjskillVectorEnv` of ``num_envs`` envs, so its
rollouts are bit for bit those of the local vector env (``examples/ppo.py --ray-workers N``).

Runs against a local Ray (``ray.init(num_cpus=2)``) or unchanged against a cluster
(``address="ray://..."`` or ``RAY_ADDRESS``). Command line::

    mjskill-ray-rollout --env PickCube-v1 --seeds 0:64 --workers 2 --out-dir shards/
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from . import _native
from ._common import live
from .envs import MAX_SEED, ROLLOUT_BUFFERS, MjskillVectorEnv, rollout_buffers

Policy = Callable[[np.ndarray], np.ndarray]


def _policy_fn(policy: str | Policy, low: np.ndarray, high: np.ndarray):
    """``(obs [n × D], seeds of the n envs, step) -> actions [n × A]``."""
    if callable(policy):
        return lambda obs, seeds, t: policy(obs)
    if policy == "zero":
        return lambda obs, seeds, t: np.zeros((len(seeds), low.shape[0]), np.float32)
    if policy == "random":
        rngs: dict[int, np.random.Generator] = {}

        def act(obs, seeds, t):
            if t == 0:
                rngs.clear()
                rngs.update({s: np.random.default_rng(s) for s in seeds})
            return np.stack([rngs[s].uniform(low, high).astype(np.float32) for s in seeds])

        return act
    raise ValueError(f"unknown policy {policy!r}; valid policies: random, zero, or a callable")


def run_shard(
    env_id: str,
    seeds: Sequence[int],
    out: str | os.PathLike,
    num_envs: int = 8,
    num_threads: int = 1,
    policy: str | Policy = "random",
    env_kwargs: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Runs the episodes of ``seeds`` (consecutive) on one native vector env and writes them
    to ``out``. Returns ``{"file", "seeds", "returns", "successes", "steps"}`` per episode.

    The recording is written by re-simulating each episode from its seed and actions in one
    env (the recorder reads a single env's state); the re-simulated returns and successes
    must equal the vector env's bit for bit, or this raises."""
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("a shard needs at least one seed")
    if any(b != a + 1 for a, b in zip(seeds, seeds[1:])):
        raise ValueError(f"shard seeds must be consecutive, got {seeds[:4]}...")
    env_kwargs = dict(env_kwargs or {})
    n = min(num_envs, len(seeds))
    vec = MjskillVectorEnv(env_id, num_envs=n, num_threads=min(num_threads, n), **env_kwargs)
    low, high = vec.single_action_space.low, vec.single_action_space.high
    act = _policy_fn(policy, low, high)
    returns: list[float] = []
    successes: list[bool] = []
    actions: list[np.ndarray] = []
    for start in range(0, len(seeds), n):
        batch = list(range(seeds[start], seeds[start] + n))
        live = np.array([s <= seeds[-1] for s in batch])
        # Each episode is its seed's, shapes included (PegInsertionSide-v1's, which a batch
        # otherwise keeps from its construction), as the single env that records it draws them.
        obs, _ = vec.reset(seed=batch[0], options={"reconfigure": True})
        done = ~live
        ret = np.zeros(n)
        success = np.zeros(n, bool)
        taken: list[list[np.ndarray]] = [[] for _ in range(n)]
        t = 0
        while not done.all():
            a = np.asarray(act(obs, batch, t), np.float32)
            obs, r, term, trunc, _ = vec.step(a)
            for i in np.flatnonzero(~done):
                taken[i].append(a[i])
                ret[i] += r[i]
                success[i] |= term[i]
            done |= term | trunc
            t += 1
        for i in np.flatnonzero(live):
            returns.append(float(ret[i]))
            successes.append(bool(success[i]))
            actions.append(np.stack(taken[i]))
    recorded = _native.record_episodes(str(out), env_id, seeds, actions, **env_kwargs)
    if [r for r, _ in recorded] != returns or [s for _, s in recorded] != successes:
        raise RuntimeError(
            f"{out}: the recording's re-simulated episodes differ from the vector env's"
        )
    return {
        "file": str(out),
        "seeds": seeds,
        "returns": returns,
        "successes": successes,
        "steps": [len(a) for a in actions],
    }


def shard_seeds(seeds: Sequence[int], num_shards: int) -> list[list[int]]:
    """Splits consecutive seeds into at most ``num_shards`` contiguous, near-equal ranges."""
    seeds = list(seeds)
    k = max(1, min(num_shards, len(seeds)))
    bounds = np.linspace(0, len(seeds), k + 1).round().astype(int)
    return [seeds[a:b] for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def merge(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Merged statistics of shard results, in seed order."""
    results = sorted(results, key=lambda r: r["seeds"][0])
    returns = [x for r in results for x in r["returns"]]
    successes = [x for r in results for x in r["successes"]]
    return {
        "episodes": len(returns),
        "successes": int(sum(successes)),
        "success_rate": float(np.mean(successes)) if successes else 0.0,
        "mean_return": float(np.mean(returns)) if returns else 0.0,
        "steps": int(sum(sum(r["steps"]) for r in results)),
        "seeds": [x for r in results for x in r["seeds"]],
        "returns": returns,
        "episode_successes": successes,
        "shards": [r["file"] for r in results],
    }


def rollout(
    env_id: str = "PickCube-v1",
    seeds: Sequence[int] = range(0, 64),
    out_dir: str | os.PathLike = "shards",
    num_workers: int = 2,
    num_envs: int = 8,
    num_threads: int = 1,
    policy: str | Policy = "random",
    use_ray: bool = True,
    address: str | None = None,
    **env_kwargs: Any,
) -> dict[str, Any]:
    """Records the episodes of ``seeds`` in ``num_workers`` shards under ``out_dir``, on Ray
    workers (each reserving ``num_threads`` CPUs) or, with ``use_ray=False``, one after the
    other in this process. Returns the merged statistics (:func:`merge`).

    ``env_kwargs`` are the env's keyword arguments (``robot_uids``, ``obs_mode``,
    ``control_mode``, ``reward_mode``, ...). Ray is initialised with ``address`` unless it
    already is."""
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("no seeds given")
    if seeds[0] < 0 or seeds[-1] > MAX_SEED:
        raise ValueError(f"seeds {seeds[0]}..{seeds[-1]} leave the 32-bit range 0..={MAX_SEED}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = [
        (s, out_dir / f"shard-{s[0]:010d}-{s[-1]:010d}.mcap")
        for s in shard_seeds(seeds, num_workers)
    ]
    if not use_ray:
        results = [
            run_shard(env_id, s, f, num_envs, num_threads, policy, env_kwargs) for s, f in jobs
        ]
        return merge(results)
    import ray

    if not ray.is_initialized():
        ray.init(address=address)
    task = ray.remote(num_cpus=num_threads)(run_shard)
    refs = [
        task.remote(env_id, s, str(f), num_envs, num_threads, policy, env_kwargs)
        for s, f in jobs
    ]
    return merge(ray.get(refs))


def shares(num_envs: int, workers: int) -> list[tuple[int, int]]:
    """``(first env, envs)`` of ``workers`` contiguous, near-equal shares of ``num_envs`` envs
    (the first ``num_envs % workers`` shares take one env more)."""
    if num_envs < 1:
        raise ValueError(f"num_envs {num_envs} is out of range: at least 1")
    if not 1 <= workers <= num_envs:
        raise ValueError(f"workers {workers} is out of range: 1..={num_envs} (num_envs)")
    q, r = divmod(num_envs, workers)
    out, first = [], 0
    for k in range(workers):
        n = q + (k < r)
        out.append((first, n))
        first += n
    return out


def check_rollout_buffers(envs: Any, buffers: Any, first_step: Any) -> int:
    """Checks, before any actor steps, what :meth:`mjskill.MjskillVectorEnv.rollout` checks
    before it steps: ``buffers`` as :func:`rollout_buffers` makes them for ``envs`` (its keys,
    exactly its dtypes and shapes for some T >= 1, C-contiguous, writable, each in its own
    memory) and ``0 <= first_step``, ``first_step + T <= 2**48``. Returns T; raises
    ``TypeError`` or ``ValueError`` naming the buffer."""
    if not isinstance(buffers, dict):
        raise TypeError(
            f"buffers must be the dict rollout_buffers(T) returns, not {type(buffers).__name__}")
    missing = [k for k in ROLLOUT_BUFFERS if k not in buffers]
    if missing:
        raise ValueError(f"buffers lack {', '.join(missing)}; rollout takes the dict "
                         f"rollout_buffers(T) returns (keys {', '.join(ROLLOUT_BUFFERS)})")
    r = buffers["rewards"]
    if not isinstance(r, np.ndarray) or r.ndim != 2 or r.shape[0] < 1:
        raise ValueError("buffers['rewards'] must be a [T, num_envs] array with T >= 1, as "
                         "rollout_buffers(T) makes it")
    steps = r.shape[0]
    want = rollout_buffers(envs, steps)
    for k in ROLLOUT_BUFFERS:
        b, w = buffers[k], want[k]
        if not isinstance(b, np.ndarray):
            raise TypeError(f"buffers[{k!r}] must be a numpy array, not {type(b).__name__}")
        if b.dtype != w.dtype or b.shape != w.shape:
            raise ValueError(f"buffers[{k!r}] is {b.dtype} {list(b.shape)}; rollout needs "
                             f"{w.dtype} {list(w.shape)} (rollout_buffers({steps}))")
        if not (b.flags.c_contiguous and b.flags.writeable):
            raise ValueError(f"buffers[{k!r}] must be C-contiguous and writable")
    for i, a in enumerate(ROLLOUT_BUFFERS):
        for b in ROLLOUT_BUFFERS[i + 1:]:
            if np.may_share_memory(buffers[a], buffers[b]):
                raise ValueError(f"buffers[{a!r}] and buffers[{b!r}] share memory; each "
                                 "buffer must have its own")
    if isinstance(first_step, bool) or not isinstance(first_step, (int, np.integer)):
        raise TypeError(f"first_step must be an integer, not {type(first_step).__name__}")
    if not 0 <= first_step <= 2**48 - steps:
        raise ValueError(f"first_step {first_step} is out of range: 0 <= first_step and "
                         f"first_step + T ({steps}) <= 2**48")
    return steps


class _RolloutActor:
    """One share of a :class:`RayVectorEnv`: envs ``first..first + n`` of the whole."""

    def __init__(self, env_id: str, first: int, n: int, num_threads: int, env_kwargs: dict):
        self.first = first
        self.vec = MjskillVectorEnv(env_id, num_envs=n, num_threads=num_threads, **env_kwargs)
        self.buffers: dict[str, np.ndarray] = {}

    def pid(self) -> int:
        """The actor's process id."""
        return os.getpid()

    def node(self) -> tuple[str, str]:
        """The Ray node the actor runs on: ``(node id, node IP address)``."""
        import ray

        return ray.get_runtime_context().get_node_id(), ray.util.get_node_ip_address()

    def spaces(self):
        v = self.vec
        return v.single_observation_space, v.single_action_space, v.max_episode_steps, {
            k: getattr(v, k) for k in ("robot_uids", "control_mode", "gripper_qvel_obs")
        }

    def reset(self, seed: int | None) -> np.ndarray:
        return self.vec.reset(seed=None if seed is None else seed + self.first)[0]

    def rollout(self, policy: dict, first_step: int, steps: int):
        from . import GaussianMlp

        if not self.buffers or self.buffers["rewards"].shape[0] != steps:
            self.buffers = self.vec.rollout_buffers(steps)
        mlp = GaussianMlp(**policy, env_offset=self.first)
        return self.buffers, self.vec.rollout(mlp, first_step, self.buffers)


class RayVectorEnv:
    """``num_envs`` envs of ``env_id`` in contiguous shares on ``workers`` Ray actors (each
    reserving ``num_threads`` CPUs and stepping its share on that many threads), for
    training: :meth:`reset` and :meth:`rollout` give bit for bit what one
    :class:`~mjskill.MjskillVectorEnv` of ``num_envs`` envs gives (env ``i`` is seeded with
    ``seed + i`` and samples its actions from its own stream, whichever actor holds it).
    Ray is initialised with ``address`` (default: ``RAY_ADDRESS`` or a local Ray) unless it
    already is. With ``spread`` (the default) Ray places the actors on as many nodes as it
    can (its ``SPREAD`` scheduling strategy), so that a cluster's nodes share the work rather
    than the first node filling up; :meth:`nodes` tells where each went.

    ``workers × num_threads`` CPUs must fit in the cluster (``ray.cluster_resources()``, the
    CPUs of the nodes up now: an autoscaling cluster's nodes must be started first), or this
    raises ``ValueError`` naming the numbers at once (Ray would otherwise wait for them
    forever). Every call waits at most ``timeout`` seconds (default 600; ``None``: no limit)
    for the actors and raises ``TimeoutError`` naming those that did not answer (a stopped
    or starved actor)."""

    def __init__(self, env_id: str, num_envs: int, workers: int, num_threads: int = 1,
                 address: str | None = None, timeout: float | None = 600.0,
                 spread: bool = True, **env_kwargs: Any):
        import ray

        num_envs = _native.check_count(num_envs, "num_envs")
        workers = _native.check_count(workers, "workers")
        num_threads = _native.check_count(num_threads, "num_threads")
        if timeout is not None and not (isinstance(timeout, (int, float))
                                        and not isinstance(timeout, bool) and timeout > 0):
            raise ValueError(f"timeout must be a positive number of seconds or None, got {timeout!r}")
        # An infinite timeout is no limit (Ray's wait takes finite seconds only).
        self.timeout = None if timeout is None or math.isinf(timeout) else float(timeout)
        self.num_envs = int(num_envs)
        self.shares = shares(self.num_envs, int(workers))
        if not ray.is_initialized():
            ray.init(address=address)
        cpus = ray.cluster_resources().get("CPU", 0)
        if workers * num_threads > cpus:
            raise ValueError(
                f"RayVectorEnv needs workers × num_threads = {workers} × {num_threads} = "
                f"{workers * num_threads} CPUs, but the Ray cluster has {cpus:g} "
                "(ray.cluster_resources()['CPU']), so its actors would never start; use fewer "
                f"workers or num_threads (at most {int(cpus)} CPUs in all)"
            )
        if not isinstance(spread, bool):
            raise TypeError(f"spread must be True or False, not {spread!r}")
        actor = ray.remote(num_cpus=num_threads,
                           scheduling_strategy="SPREAD" if spread else "DEFAULT")(_RolloutActor)
        self._actors = [actor.remote(env_id, f, n, num_threads, env_kwargs)
                        for f, n in self.shares]
        obs_space, act_space, steps, attrs = self._get(
            [self._actors[0].spaces.remote()], "start")[0]
        self.single_observation_space, self.single_action_space = obs_space, act_space
        self.max_episode_steps = steps
        for k, v in attrs.items():
            setattr(self, k, v)

    def _get(self, refs: list, what: str) -> list:
        """``ray.get(refs)`` within :attr:`timeout`, or a ``TimeoutError`` naming the actors
        (``refs[k]`` is actor ``k``'s answer) that did not answer."""
        import ray

        if self.timeout is None:
            return ray.get(refs)
        ready, pending = ray.wait(refs, num_returns=len(refs), timeout=self.timeout)
        if pending:
            late = [k for k, r in enumerate(refs) if r in pending]
            raise TimeoutError(
                f"RayVectorEnv: actor(s) {late} (envs "
                + ", ".join(f"{self.shares[k][0]}..{sum(self.shares[k]) - 1}" for k in late)
                + f") did not answer {what} within {self.timeout:g} s (stopped, busy or "
                "starved of CPUs); the timeout is RayVectorEnv(timeout=...)"
            )
        return ray.get(refs)

    def nodes(self) -> list[tuple[str, str]]:
        """Where each actor runs: ``(Ray node id, node IP address)`` per actor, in the order of
        :attr:`shares`."""
        return self._get([a.node.remote() for a in self._live()], "nodes")

    def _live(self) -> list:
        """The actors, or a ``RuntimeError`` once :meth:`close` has ended them."""
        return live(self._actors or None, "this RayVectorEnv", "make a new one")

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Resets every env (env ``i`` with ``seed + i``); the observations ``[N, obs_dim]``."""
        actors = self._live()
        seed = _native.check_seed(seed)
        if seed is not None and seed + self.num_envs - 1 > MAX_SEED:
            raise ValueError(
                f"seed {seed} is out of range for these envs: env i is seeded with seed + i, and "
                f"env {self.num_envs - 1} would get {seed + self.num_envs - 1}, beyond the 32-bit "
                f"seeds 0..={MAX_SEED}; give a seed at most {MAX_SEED - self.num_envs + 1}"
            )
        return np.concatenate(self._get([a.reset.remote(seed) for a in actors], "reset"))

    def rollout_buffers(self, steps: int) -> dict[str, np.ndarray]:
        """As :meth:`mjskill.MjskillVectorEnv.rollout_buffers`, for all ``num_envs`` envs."""
        return rollout_buffers(self, steps)

    def rollout(self, policy: dict, first_step: int, buffers: dict[str, np.ndarray]) -> np.ndarray:
        """:meth:`mjskill.MjskillVectorEnv.rollout` on every share at once. ``policy`` holds
        :class:`~mjskill.GaussianMlp`'s keyword arguments (``layers``, ``obs_mean``,
        ``obs_std``, ``obs_clip``, ``std``, ``seed``); each actor builds it with its share's
        ``env_offset``. Fills ``buffers`` and returns the observations after the last step."""
        import ray

        actors = self._live()
        steps = check_rollout_buffers(self, buffers, first_step)
        ref = ray.put(policy)
        parts = self._get(
            [a.rollout.remote(ref, first_step, steps) for a in actors], "rollout")
        for key, dst in buffers.items():
            np.concatenate([p[0][key] for p in parts], axis=1, out=dst)
        return np.concatenate([p[1] for p in parts])

    def close(self) -> None:
        """Ends the actors."""
        import ray

        for a in self._actors:
            ray.kill(a)
        self._actors = []


def main(argv: Sequence[str] | None = None) -> int:
    """``mjskill-ray-rollout``: prints the merged statistics as JSON."""
    p = argparse.ArgumentParser(prog="mjskill-ray-rollout", description=__doc__.split("\n")[0])
    p.add_argument("--env", default="PickCube-v1")
    p.add_argument("--robot-uids")
    p.add_argument("--obs-mode", default="state")
    p.add_argument("--control-mode")
    p.add_argument("--reward-mode", default="normalized_dense")
    p.add_argument("--seeds", default="0:64", help="START:END (END exclusive)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--num-envs", type=int, default=8)
    p.add_argument("--threads", type=int, default=1, help="threads (and Ray CPUs) per worker")
    p.add_argument("--policy", default="random", choices=["random", "zero"])
    p.add_argument("--out-dir", default="shards")
    p.add_argument("--address", help="Ray cluster address (default: RAY_ADDRESS or local)")
    p.add_argument("--no-ray", action="store_true", help="run the shards in this process")
    a = p.parse_args(argv)
    try:
        start, end = (int(x) for x in a.seeds.split(":"))
    except ValueError:
        p.error(f"--seeds {a.seeds!r} is not START:END, e.g. 0:64")
    kw = {
        "robot_uids": a.robot_uids,
        "obs_mode": a.obs_mode,
        "control_mode": a.control_mode,
        "reward_mode": a.reward_mode,
    }
    stats = rollout(
        a.env, range(start, end), a.out_dir, a.workers, a.num_envs, a.threads, a.policy,
        use_ray=not a.no_ray, address=a.address, **kw,
    )
    for k in ("returns", "episode_successes", "seeds"):
        stats.pop(k)
    print(json.dumps(stats))
    return 0

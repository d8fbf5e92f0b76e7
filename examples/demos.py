"""Demonstrations for examples/ppo.py ``--demos`` and examples/imitate.py: episodes recorded by
``mjskill rollout`` (MCAP) and ManiSkill's trajectory format (``.h5`` with its ``.json``, as
``mjskill export --format maniskill`` and ManiSkill write), read into flat arrays of
(observation, action, discounted return) for the steps of successful episodes, up to and
including their first success (mjskill's training env ends an episode there).

A recording of noise-injected demonstrations (``mjskill rollout --action-noise``) holds two
actions per step: the one the env executed (``action``, which the states follow) and the
expert's own (``expert_action``), the label to clone: ``Episode.labels`` and
``Demos.labels``/``Demos.all_labels`` (the executed actions where a file has no labels).

Every file is checked before any env is built: the env id, robot, observation mode and size,
and control mode must agree across files and with the run; empty, damaged and failed-only
files are errors naming the file and what was wrong. docs/training.md, "Learning from
demonstrations", describes the method that uses them.

    demos = load(["demos.mcap"], env_id="PickCube-v1", robot=None, control_mode=None)
    demos.obs, demos.actions, demos.returns(gamma=0.8)
"""

from __future__ import annotations

import json
import os
import stat
from dataclasses import dataclass, field

import numpy as np

#: The largest demo file read (bytes): a bound on memory for a hostile or mistaken path.
MAX_FILE_BYTES = 4 << 30


class DemoError(ValueError):
    """A demonstration file that cannot be used, with the file and the reason."""


@dataclass
class Episode:
    obs: np.ndarray  # (T, D): the observation before each action
    actions: np.ndarray  # (T, A)
    rewards: np.ndarray  # (T,)
    success: bool  # the episode reached success
    seed: int | None = None
    #: Steps up to and including the first success (all when it never succeeded): the
    #: steps the training env, which ends an episode at success, visits.
    n_until_success: int | None = None
    #: Per step: the task's success after the step (None: not recorded).
    successes: np.ndarray | None = None
    #: (T, A): the expert's own action at each step, where ``actions`` holds the executed
    #: one (recordings of ``mjskill rollout --action-noise``); None when not recorded.
    labels: np.ndarray | None = None

    def __post_init__(self):
        if self.n_until_success is None:
            self.n_until_success = len(self.actions)


@dataclass
class Demos:
    """Episodes of one (env, robot, control mode), with where they came from."""

    env_id: str
    robot: str
    control_mode: str
    obs_dim: int | None
    episodes: list[Episode] = field(default_factory=list)
    files: list[str] = field(default_factory=list)
    skipped_failed: int = 0
    #: Failed episodes kept (``load(..., keep_failed=True)``).
    kept_failed: int = 0
    #: Episodes of ManiSkill h5 files without observations: (seed, actions) to replay.
    to_replay: list[tuple[int, np.ndarray]] = field(default_factory=list)

    @property
    def obs(self) -> np.ndarray:
        """The observations of the steps up to each episode's first success."""
        return np.concatenate([e.obs[:e.n_until_success] for e in self.episodes]
                              ).astype(np.float32)

    @property
    def actions(self) -> np.ndarray:
        """The actions of the steps up to each episode's first success."""
        return np.concatenate([e.actions[:e.n_until_success] for e in self.episodes]
                              ).astype(np.float32)

    @property
    def labels(self) -> np.ndarray:
        """The labels to clone for the steps up to each episode's first success: the expert's
        own actions where recorded (noise-injected demos), else the executed actions."""
        return np.concatenate([_labels(e)[:e.n_until_success] for e in self.episodes]
                              ).astype(np.float32)

    @property
    def all_labels(self) -> np.ndarray:
        """``labels`` for every recorded step (after the first success too)."""
        return np.concatenate([_labels(e) for e in self.episodes]).astype(np.float32)

    @property
    def labelled(self) -> int:
        """How many episodes carry the expert's own labels."""
        return sum(e.labels is not None for e in self.episodes)

    @property
    def seeds(self) -> set:
        """The reset seeds of the episodes (those recorded)."""
        return {e.seed for e in self.episodes if e.seed is not None}

    @property
    def all_obs(self) -> np.ndarray:
        """The observations of every recorded step (after the first success too)."""
        return np.concatenate([e.obs for e in self.episodes]).astype(np.float32)

    def returns(self, gamma: float, reward_mode: str = "normalized_dense") -> np.ndarray:
        """The discounted return of every recorded step (``all_obs``'s), the episode's end
        bootstrapped as if its last reward went on (r/(1-gamma)): ppo.py bootstraps the value
        of the final observation at every episode end, success included, so a success state
        is worth what holding it earns."""
        out = []
        for e in self.episodes:
            rewards = e.rewards
            if reward_mode == "sparse":
                # ManiSkill's sparse reward is the success flag.
                rewards = np.asarray(e.successes, np.float64)
            elif reward_mode != "normalized_dense":
                raise DemoError(f"demo returns for reward mode {reward_mode!r}: the demos' "
                                "rewards are normalized_dense; sparse is their success flag")
            r = np.zeros(len(rewards))
            g = rewards[-1] / (1.0 - gamma) if gamma < 1 else 0.0
            for t in reversed(range(len(rewards))):
                g = rewards[t] + gamma * g
                r[t] = g
            out.append(r)
        return np.concatenate(out).astype(np.float32)

    @property
    def steps(self) -> int:
        return sum(e.n_until_success for e in self.episodes)


def _labels(e: Episode) -> np.ndarray:
    return e.actions if e.labels is None else e.labels


def _check_path(path: str) -> None:
    try:
        st = os.stat(path)
    except OSError as e:
        raise DemoError(f"--demos {path}: cannot read it ({e.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise DemoError(f"--demos {path}: not a regular file (a recording .mcap or a "
                        "ManiSkill trajectory .h5)")
    if st.st_size == 0:
        raise DemoError(f"--demos {path}: the file is empty")
    if st.st_size > MAX_FILE_BYTES:
        raise DemoError(f"--demos {path}: {st.st_size} bytes, more than the {MAX_FILE_BYTES} "
                        "read")


def _first_success(success_flags):
    """(whether any step succeeds, the steps up to and including the first success)."""
    hits = np.flatnonzero(np.asarray(success_flags, bool))
    return (True, int(hits[0]) + 1) if len(hits) else (False, len(success_flags))


def read_mcap(path: str) -> tuple[dict, list[Episode]]:
    """(metadata, episodes) of an mjskill recording."""
    try:
        from mcap.reader import make_reader
    except ImportError:
        raise DemoError(f"--demos {path}: reading MCAP recordings needs the `mcap` package "
                        "(pip install mcap, or the extra mjskill[train])") from None
    meta = None
    eps: dict[int, dict] = {}
    try:
        with open(path, "rb") as f:
            magic = f.read(8)
            if magic != b"\x89MCAP0\r\n":
                raise DemoError(f"--demos {path}: not an MCAP file (it starts with "
                                f"{magic[:8]!r})")
            f.seek(0)
            reader = make_reader(f)
            for _, channel, message in reader.iter_messages(
                    topics=["/episode", "/step", "/episode_end"]):
                m = json.loads(message.data)
                k = int(m["episode"])
                if channel.topic == "/episode":
                    eps[k] = dict(seed=m.get("seed"), obs=[m["obs"]], actions=[], rewards=[],
                                  term=[], success=None, labels=[])
                elif k in eps and channel.topic == "/step":
                    e = eps[k]
                    e["actions"].append(m["action"])
                    e["labels"].append(m.get("expert_action"))
                    e["rewards"].append(m["reward"])
                    e["term"].append(bool(m["terminated"]) or bool(m["info"].get("success")))
                    e["obs"].append(m["obs"])
                elif k in eps:
                    eps[k]["success"] = bool(m["success"])
            f.seek(0)
            for rec in make_reader(f).iter_metadata():
                if rec.name == "mjskill":
                    meta = dict(rec.metadata)
    except DemoError:
        raise
    except Exception as e:  # the mcap reader's errors for a damaged file vary
        # A recording cut short keeps its finished episodes: use what was read.
        if not eps:
            raise DemoError(f"--demos {path}: a damaged or unreadable MCAP file "
                            f"({type(e).__name__}: {e})") from None
    if meta is None:
        raise DemoError(f"--demos {path}: no `mjskill` metadata record: not a recording of "
                        "`mjskill rollout`")
    episodes = []
    for k in sorted(eps):
        e = eps[k]
        if e["success"] is None or not e["actions"]:
            continue  # unfinished: the recording was cut short
        obs = np.asarray([[np.nan if v is None else v for v in o] for o in e["obs"][:-1]],
                         np.float64)
        act = np.asarray(e["actions"], np.float64)
        rew = np.asarray([np.nan if r is None else r for r in e["rewards"]], np.float64)
        ok, n = _first_success(e["term"])
        labelled = [x is not None for x in e["labels"]]
        if any(labelled) and not all(labelled):
            raise DemoError(f"--demos {path}: episode {k} (seed {e['seed']}) has an "
                            f"expert_action on {sum(labelled)} of its {len(labelled)} steps; a "
                            "recording labels every step or none")
        labels = None
        if all(labelled):
            labels = np.asarray([[np.nan if v is None else v for v in a] for a in e["labels"]],
                                np.float64)
            if labels.shape != act.shape:
                raise DemoError(f"--demos {path}: episode {k} (seed {e['seed']}) has labels "
                                f"of shape {labels.shape} for actions of shape {act.shape}")
        episodes.append(Episode(obs, act, rew, ok, e["seed"], n, np.asarray(e["term"], bool),
                                labels))
    return meta, episodes


def read_h5(path: str) -> tuple[dict, list[Episode], list[tuple[int, np.ndarray]]]:
    """(env info, episodes with observations, (seed, actions) of those without) of a
    ManiSkill trajectory file."""
    try:
        import h5py
    except ImportError:
        raise DemoError(f"--demos {path}: reading ManiSkill .h5 files needs `h5py` "
                        "(pip install h5py, or the extra mjskill[train])") from None
    jpath = os.path.splitext(path)[0] + ".json"
    try:
        with open(jpath) as f:
            info = json.load(f)
        env_info = info["env_info"]
        listed = info["episodes"]
    except FileNotFoundError:
        raise DemoError(f"--demos {path}: its json ({jpath}) is missing; ManiSkill's "
                        "trajectory format keeps env and episode information there") from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise DemoError(f"--demos {path}: its json {jpath} is damaged ({e})") from None
    episodes, to_replay = [], []
    try:
        with h5py.File(path, "r") as h:
            for ep in listed:
                name = f"traj_{int(ep['episode_id'])}"
                if name not in h:
                    raise DemoError(f"--demos {path}: the json lists {name}, which the file "
                                    "does not hold")
                g = h[name]
                act = np.asarray(g["actions"], np.float64)
                succ = np.asarray(g["success"], bool) if "success" in g else \
                    np.zeros(len(act), bool)
                if act.ndim != 2 or len(act) == 0 or len(succ) != len(act):
                    raise DemoError(f"--demos {path}: {name} has actions of shape {act.shape} "
                                    f"and {len(succ)} success flags")
                seed = (ep.get("reset_kwargs") or {}).get("seed", ep.get("episode_seed"))
                if isinstance(seed, list):
                    seed = seed[0]
                obs = g.get("obs")
                if obs is None or not isinstance(obs, h5py.Dataset):
                    if succ.any() and seed is not None:
                        to_replay.append((int(seed), act))
                    else:
                        to_replay.append((None, None))  # counted as failed
                    continue
                obs = np.asarray(obs, np.float64)
                if obs.ndim != 2 or len(obs) != len(act) + 1:
                    raise DemoError(f"--demos {path}: {name} has obs of shape {obs.shape} for "
                                    f"{len(act)} actions (expected ({len(act) + 1}, D), the "
                                    "state obs mode)")
                rew = np.asarray(g["rewards"], np.float64) if "rewards" in g else \
                    np.zeros(len(act))
                ok, n = _first_success(succ)
                episodes.append(Episode(obs[:-1], act, rew, ok,
                                        None if seed is None else int(seed), n, succ))
    except DemoError:
        raise
    except Exception as e:
        raise DemoError(f"--demos {path}: a damaged or unreadable HDF5 file "
                        f"({type(e).__name__}: {e})") from None
    kw = env_info.get("env_kwargs", {})
    robot = kw.get("robot_uids")
    if isinstance(robot, list):
        robot = robot[0] if robot else None
    mode = kw.get("control_mode") or (listed[0].get("control_mode") if listed else None)
    meta = dict(env_id=env_info.get("env_id"), robot=robot, control_mode=mode,
                obs_mode=kw.get("obs_mode") or "none")
    return meta, episodes, to_replay


def load(paths, env_id: str | None, robot: str | None, control_mode: str | None,
         trainer: str = "ppo.py", keep_failed: bool = False) -> Demos:
    """Reads and checks every file; ``env_id``/``robot``/``control_mode`` None take the demos'
    own (``trainer`` names the script in the advice on control modes). Failed episodes are
    left out and counted (``skipped_failed``), or with ``keep_failed`` kept too (counted in
    ``kept_failed``): noise-injected demos label every visited state with the expert's
    action, whatever the episode's outcome."""
    if not paths:
        raise DemoError("--demos needs at least one file")
    demos = None
    for path in paths:
        _check_path(path)
        with open(path, "rb") as f:
            head = f.read(8)
        if head == b"\x89MCAP0\r\n":
            meta, eps = read_mcap(path)
            to_replay = []
            if meta.get("obs_mode") not in ("state", "state_dict"):
                raise DemoError(f"--demos {path}: recorded with obs_mode "
                                f"{meta.get('obs_mode')!r}; training uses state observations "
                                "(record with --obs-mode state)")
            try:
                dim = int(json.loads(meta["observation_space"])["shape"][0])
            except (KeyError, ValueError, TypeError, IndexError):
                raise DemoError(f"--demos {path}: its metadata has no observation_space "
                                "shape") from None
            m = dict(env_id=meta.get("env_id"), robot=meta.get("robot"),
                     control_mode=meta.get("control_mode"))
        elif head == b"\x89HDF\r\n\x1a\n":
            m, eps, to_replay = read_h5(path)
            if eps and m["obs_mode"] not in ("state", "state_dict"):
                raise DemoError(f"--demos {path}: observations recorded with obs_mode "
                                f"{m['obs_mode']!r}; training uses state observations")
            dim = eps[0].obs.shape[1] if eps else None
        else:
            raise DemoError(f"--demos {path}: neither an MCAP recording nor an HDF5 file "
                            f"(it starts with {head!r})")
        want_env = env_id or (demos.env_id if demos else None)
        if want_env is not None and m["env_id"] != want_env:
            raise DemoError(f"--demos {path}: episodes of {m['env_id']}, but this run trains "
                            f"{want_env}")
        want_robot = robot or (demos.robot if demos else None)
        if want_robot is not None and m["robot"] is not None and m["robot"] != want_robot:
            raise DemoError(f"--demos {path}: episodes of robot {m['robot']}, but this run "
                            f"trains {want_robot}")
        want_mode = control_mode or (demos.control_mode if demos else None)
        if want_mode is not None and m["control_mode"] != want_mode:
            raise DemoError(
                f"--demos {path}: actions in control mode {m['control_mode']}, but this run "
                f"trains in {want_mode}; {trainer} does not convert actions: record the demos in "
                f"{want_mode} (`mjskill rollout --policy solver --control-mode {want_mode}` "
                "converts the solver's actions as it runs) or leave --control-mode out to "
                f"train in {m['control_mode']}")
        if demos is None:
            demos = Demos(m["env_id"], m["robot"] or robot, m["control_mode"], dim)
        elif dim is not None and demos.obs_dim is not None and dim != demos.obs_dim:
            raise DemoError(f"--demos {path}: observations of {dim} values, the other files' "
                            f"have {demos.obs_dim}")
        demos.obs_dim = demos.obs_dim or dim
        for e in eps:
            if e.obs.shape[1] != demos.obs_dim or np.isnan(e.obs).any() or \
                    np.isnan(e.actions).any() or (e.labels is not None
                                                  and np.isnan(e.labels).any()):
                raise DemoError(f"--demos {path}: an episode (seed {e.seed}) has observations "
                                f"of {e.obs.shape[1]} values or non-finite values")
            if e.success or keep_failed:
                demos.episodes.append(e)
                demos.kept_failed += not e.success
            else:
                demos.skipped_failed += 1
        for seed, act in to_replay:
            if act is None:
                demos.skipped_failed += 1
            else:
                demos.to_replay.append((seed, act))
        demos.files.append(path)
    if not demos.episodes and not demos.to_replay:
        raise DemoError(f"--demos {' '.join(paths)}: no successful episode "
                        f"({demos.skipped_failed} failed, none finished with success)")
    return demos


def replay_missing_obs(demos: Demos, make_env) -> None:
    """Episodes of h5 files without observations: replayed by their actions from their seed in
    ``make_env()`` (an mjskill env of the run's pair; gymnasium's next-step autoreset is not
    involved: one env, stepped to the episode's length), keeping those that succeed here
    too."""
    if not demos.to_replay:
        return
    env = make_env()
    try:
        for seed, act in demos.to_replay:
            obs, _ = env.reset(seed=seed)
            o, r, first, su = [], [], None, []
            for a in act:
                o.append(obs)
                obs, rew, term, trunc, info = env.step(a.astype(np.float32))
                r.append(rew)
                su.append(bool(term) or bool(info.get("success", False)))
                if first is None and (term or bool(info.get("success", False))):
                    first = len(o)
                if term or trunc:
                    break
            n = len(o)
            if first is not None:
                demos.episodes.append(Episode(np.asarray(o, np.float64), act[:n],
                                              np.asarray(r, np.float64), True, seed, first,
                                              np.asarray(su, bool)))
            else:
                demos.skipped_failed += 1
    finally:
        env.close()
    demos.to_replay = []
    if demos.episodes:
        demos.obs_dim = demos.episodes[0].obs.shape[1]
    else:
        raise DemoError(f"--demos {' '.join(demos.files)}: none of the episodes without "
                        "observations succeeds when replayed by actions in mjskill")


def pretrain(actor, critic, obs, actions, value_obs, returns, epochs: int, batch: int = 512,
             lr: float = 1e-3, seed: int = 0, obs_noise: float = 0.0, log=print):
    """Behaviour cloning of the actor's mean (mean squared error to the demo ``actions`` at
    ``obs``) and a fit of the critic to the demos' discounted ``returns`` at ``value_obs``,
    ``epochs`` passes each (observations normalised, on the learner's device), the actor's
    inputs with Gaussian noise of std ``obs_noise`` (in normalised units: a cloned policy
    that has seen states a little off the demos' recovers from them). Returns the final
    (bc, value) mean squared errors."""
    import torch

    g = torch.Generator().manual_seed(seed)
    losses = []
    for net, x, target, what in ((actor, obs, actions, "actor (behaviour cloning)"),
                                 (critic, value_obs, returns.view(-1, 1),
                                  "critic (demo returns)")):
        n = x.shape[0]
        opt = torch.optim.Adam(net.parameters(), lr=lr)
        last = float("nan")
        for ep in range(epochs):
            perm = torch.randperm(n, generator=g).to(x.device)
            total = 0.0
            for s in range(0, n, batch):
                idx = perm[s:s + batch]
                xi = x[idx]
                if net is actor and obs_noise > 0:
                    xi = xi + obs_noise * torch.randn(xi.shape, generator=g).to(xi.device)
                loss = ((net(xi) - target[idx]) ** 2).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
                total += float(loss.detach()) * len(idx)
            last = total / n
            if ep == 0 or ep == epochs - 1:
                log(f"pretrain {what}: epoch {ep + 1}/{epochs}, mse {last:.5f}")
        losses.append(last)
    return tuple(losses)

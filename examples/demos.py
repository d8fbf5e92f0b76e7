"""Demonstrations for examples/ppo.py ``--demos`` and examples/imitate.py: episodes recorded by
``mjskill rollout`` (MCAP) and ManiSkill's trajectory format (``.h5`` with its ``.json``, as
``mjskill export --format maniskill`` and ManiSkill write), read into flat arrays of
(observation, action, discounted return) for the steps of successful episodes, up to and
including their first success (mjskill's training env ends an episode there).

A recording of noise-injected demonstrations (``mjskill rollout --action-noise``) holds two
actions per step: the one the env executed (``action``, which the states follow) and the
expert's own (``expert_action``), the label to clone: ``Episode.labels`` and
``Demos.labels``/``Demos.all_labels`` (the executed actions where a file has no labels).

Every file is read and checked before the run's envs are built (docs/training.md, "Learning
from demonstrations"):

* every file opened (the ``.json`` beside an ``.h5`` too) is a regular file, never a FIFO or
  device, of bounded size (training.files.open_regular);
* recordings are read with the checks of mjskill's own reader (training.recording: chunk,
  data and summary CRCs, structure, the messages' order): a damaged file is refused, one cut
  short keeps its finished episodes (``Demos.notes`` says so);
* what a file yields is bounded by its size (:data:`VALUES_PER_BYTE` values per byte), checked
  against each declared size before anything is allocated, so a small file that declares
  millions of steps is refused instead of filling memory;
* every observation, action, label and reward is finite in float32, every action and label
  within the action space, and every length consistent (rewards and success flags one per
  action, observations one more), with errors naming the file, episode, step and value;
* the env id, robot, observation mode and size, and control mode agree across files and with
  the run; given ``spaces``, the demos are checked against the run's observation and action
  spaces (one env made for them, before the run's envs);
* a file given twice, or an episode listed twice in a json, is refused.

    demos = load(["demos.mcap"], env_id="PickCube-v1", robot=None, control_mode=None)
    demos.obs, demos.actions, demos.returns(gamma=0.8)
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from training import recording  # noqa: E402
from training.files import (  # noqa: E402
    FileCheckError, changed_since, fingerprint, open_regular, read_regular)

#: The largest demo file read (bytes).
MAX_FILE_BYTES = 4 << 30
#: The largest ``.json`` beside an ``.h5`` read (bytes).
MAX_JSON_BYTES = 64 << 20
#: The most values (observations, actions, labels, rewards, flags) a file yields per byte of
#: its size: memory follows what a file holds, not what it declares. Uncompressed files hold
#: at least 4 bytes per value, recordings about 10 (JSON text, compressed).
VALUES_PER_BYTE = 16
#: ... and at least this many, whatever its size.
MIN_VALUES = 1 << 20
#: The largest recording message decoded (bytes); mjskill's state-observation messages are
#: tens of KB.
MAX_MESSAGE_BYTES = 4 << 20
#: The largest magnitude training takes (float32).
F32_MAX = float(np.finfo(np.float32).max)


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
    #: How messages name the episode: ``episode K (seed S)``, ``traj_K (seed S)``.
    name: str = ""

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
    #: The size of the actions.
    act_dim: int | None = None
    #: What the trainer tells the user about the files (a recording cut short, read up to
    #: the cut).
    notes: list[str] = field(default_factory=list)
    #: The commands that recorded the files, where a recording keeps one (``mjskill rollout``
    #: writes its own, without ``--out``, into the metadata key ``command``).
    commands: list[str] = field(default_factory=list)

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


class _Budget:
    """The values a file may yield: :data:`VALUES_PER_BYTE` per byte of its size (at least
    :data:`MIN_VALUES`), taken before each array is read or built."""

    def __init__(self, path, size):
        self.path, self.size = path, size
        self.limit = self.left = max(MIN_VALUES, VALUES_PER_BYTE * size)

    def take(self, n, what):
        if n > self.left:
            raise DemoError(f"--demos {self.path}: {what} would bring the values read from "
                            f"this {self.size}-byte file past {self.limit} ({VALUES_PER_BYTE} "
                            "per byte of the file): a damaged file, or one whose declared "
                            "sizes its data does not hold")
        self.left -= n


def _first_success(success_flags):
    """(whether any step succeeds, the steps up to and including the first success)."""
    hits = np.flatnonzero(np.asarray(success_flags, bool))
    return (True, int(hits[0]) + 1) if len(hits) else (False, len(success_flags))


def _is_int(x):
    return isinstance(x, int) and not isinstance(x, bool)


def _is_number(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)


class _Msg(Exception):
    """A recording message that is not what mjskill writes (the reason)."""


def _vector(m, key, n=None):
    """``m[key]``, a list of numbers (null: a value that was not finite when recorded, read
    as NaN), as float64; of length ``n`` unless None."""
    v = m.get(key)
    if not isinstance(v, list) or not all(x is None or _is_number(x) for x in v):
        raise _Msg(f"{key} is not a list of numbers")
    if n is not None and len(v) != n:
        raise _Msg(f"{key} has {len(v)} values, not {n}")
    return np.array([np.nan if x is None else x for x in v], np.float64)


def _bound(x, inf):
    """A space bound as mjskill's metadata writes it: a number, or "inf"/"-inf" (null: no
    bound, ``inf``)."""
    if x is None:
        return inf
    if _is_number(x):
        return float(x)
    if x in ("inf", "-inf"):
        return float(x)
    raise ValueError(f"bound {x!r}")


def _space(meta, key, path):
    """A recording's ``observation_space``/``action_space`` metadata: (size, low, high)."""
    try:
        sp = json.loads(meta[key])
        (dim,) = sp["shape"]
        low, high = sp["low"], sp["high"]
        if not (_is_int(dim) and dim > 0 and isinstance(low, list) and isinstance(high, list)
                and len(low) == len(high) == dim):
            raise ValueError
        low = np.array([_bound(x, -np.inf) for x in low], np.float64)
        high = np.array([_bound(x, np.inf) for x in high], np.float64)
    except (KeyError, ValueError, TypeError):
        raise DemoError(f"--demos {path}: its metadata has no valid {key} (a shape of one "
                        "size and its bounds)") from None
    return dim, low, high


def read_mcap(path: str, f=None, size=None) -> tuple[dict, list[Episode], str | None]:
    """(metadata, finished episodes, where the file was cut short or None) of an mjskill
    recording, read with mjskill's own checks (training.recording). The metadata has
    ``obs_dim`` and the action space's ``act_low``/``act_high`` parsed."""
    if f is None:
        with _open_demo(path) as f:
            return read_mcap(path, f, os.fstat(f.fileno()).st_size)
    try:
        import zstandard  # noqa: F401  (the chunks' compression)
    except ImportError:
        raise DemoError(f"--demos {path}: reading MCAP recordings needs the `zstandard` "
                        "package (pip install mcap, which brings it, or the extra "
                        "mjskill[train])") from None
    budget = _Budget(path, size)
    meta = None
    episode_meta = None  # (index, seed text) of the last episode-N record
    eps: dict[int, dict] = {}
    state = {"open": None, "last": None}  # the open episode, the last one begun

    def on_metadata(name, m, at):
        nonlocal meta, episode_meta
        if name == "mjskill":
            if meta is not None:
                raise recording.Damaged(at, "a second `mjskill` metadata record")
            mode = m.get("obs_mode")
            if mode not in ("state", "state_dict"):
                raise DemoError(f"--demos {path}: recorded with obs_mode {mode!r}; training "
                                "uses state observations (record with --obs-mode state)")
            meta = dict(m)
            meta["obs_dim"] = _space(meta, "observation_space", path)[0]
            _, meta["act_low"], meta["act_high"] = _space(meta, "action_space", path)
            return
        if not name.startswith("episode-"):
            raise recording.Damaged(at, f"unexpected metadata record {name!r}")
        if meta is None:
            raise recording.Damaged(at, f"metadata record {name!r} before the `mjskill` one")
        expect = 0 if episode_meta is None else episode_meta[0] + 1
        if name != f"episode-{expect}" or m.get("episode") != str(expect):
            raise recording.Damaged(at, f"metadata record {name!r} where episode-{expect} "
                                        "belongs")
        rest = {k: v for k, v in m.items() if k not in ("episode", "seed")}
        file_map = {k: v for k, v in meta.items()
                    if k not in ("obs_dim", "act_low", "act_high")}
        if rest != file_map:
            raise recording.Damaged(at, f"metadata record {name!r} differs from the file's "
                                        "`mjskill` record")
        episode_meta = (expect, m.get("seed", ""))

    def on_message(topic, data, where):
        if topic not in ("/episode", "/step", "/episode_end"):
            return
        if meta is None:
            raise DemoError(f"--demos {path}: a {topic} message in {where} comes before the "
                            "`mjskill` metadata record: the file is damaged")
        if len(data) > MAX_MESSAGE_BYTES:
            raise DemoError(f"--demos {path}: a {topic} message in {where} has {len(data)} "
                            f"bytes, more than the {MAX_MESSAGE_BYTES} of a state-observation "
                            "recording's")
        try:
            m = json.loads(data)
        except (ValueError, RecursionError) as e:  # JSONDecodeError, UnicodeDecodeError
            raise DemoError(f"--demos {path}: the {topic} message in {where} is not valid "
                            f"JSON ({e}): the file is damaged") from None
        try:
            if not isinstance(m, dict):
                raise _Msg("not a JSON object")
            _message(topic, m)
        except _Msg as e:
            raise DemoError(f"--demos {path}: the {topic} message in {where} does not decode "
                            f"as mjskill writes it: {e}; the file is damaged") from None

    def _message(topic, m):
        k = m.get("episode")
        if not _is_int(k) or k < 0:
            raise _Msg("no episode index")
        dim, act_dim = meta["obs_dim"], len(meta["act_low"])
        if topic == "/episode":
            seed = m.get("seed")
            if not (seed is None or _is_int(seed)):
                raise _Msg(f"episode {k}: its seed is not an integer")
            seed_text = "null" if seed is None else str(seed)
            if episode_meta is None or episode_meta != (k, seed_text):
                raise _Msg(f"episode {k} (seed {seed_text}) does not match the last episode "
                           f"metadata record {episode_meta}")
            if k == state["last"] or k in eps:
                raise _Msg(f"episode {k} begins twice")
            budget.take(dim + 8, f"episode {k}")
            eps[k] = dict(seed=seed, obs=[_vector(m, "obs", dim)], actions=[], rewards=[],
                          term=[], success=None, labels=[])
            state["open"], state["last"] = k, k
            return
        if state["open"] != k:
            raise _Msg(f"episode {k} is not open")
        e = eps[k]
        n = len(e["actions"])
        if topic == "/step":
            if m.get("step") != n:
                raise _Msg(f"step {m.get('step')} of episode {k} follows {n} steps")
            budget.take(dim + 2 * act_dim + 8, f"episode {k}, step {n}")
            action = _vector(m, "action", act_dim)
            label = None
            if m.get("expert_action") is not None:
                label = _vector(m, "expert_action", act_dim)
            reward = m.get("reward")
            if not (reward is None or _is_number(reward)):
                raise _Msg(f"episode {k}, step {n}: reward is not a number")
            info = m.get("info")
            if not (isinstance(m.get("terminated"), bool) and isinstance(info, dict)):
                raise _Msg(f"episode {k}, step {n}: no terminated flag or info")
            e["actions"].append(action)
            e["labels"].append(label)
            e["rewards"].append(np.nan if reward is None else float(reward))
            e["term"].append(m["terminated"] or bool(info.get("success")))
            e["obs"].append(_vector(m, "obs", dim))
        else:
            if m.get("steps") != n or not isinstance(m.get("success"), bool):
                raise _Msg(f"end of episode {k} after {m.get('steps')} steps does not match "
                           f"its {n} steps, or has no success flag")
            e["success"] = m["success"]
            state["open"] = None

    magic = f.read(8)
    if magic != recording.MAGIC:
        if recording.MAGIC.startswith(magic):
            raise DemoError(f"--demos {path}: cut short at byte {len(magic)}, inside the MCAP "
                            "magic")
        raise DemoError(f"--demos {path}: not an MCAP file (it starts with {magic!r})")
    try:
        complete, cut = recording.scan(f, size, path, on_metadata, on_message)
    except recording.Damaged as e:
        raise DemoError(f"--demos {path}: a damaged MCAP file, refused whole (no episode of "
                        f"it is used): {e}") from None
    except recording.NotRecording as e:
        raise DemoError(f"--demos {path}: {e}") from None
    if meta is None:
        if cut:
            raise DemoError(f"--demos {path}: cut short ({cut}) before its `mjskill` metadata "
                            "record")
        raise DemoError(f"--demos {path}: no `mjskill` metadata record: not a recording of "
                        "`mjskill rollout`")
    episodes = []
    for k in sorted(eps):
        e = eps[k]
        if e["success"] is None:
            continue  # unfinished: the recording was cut short
        name = f"episode {k} (seed {e['seed']})"
        if not e["actions"]:
            continue
        labelled = [x is not None for x in e["labels"]]
        if any(labelled) and not all(labelled):
            raise DemoError(f"--demos {path}: {name} has an expert_action on "
                            f"{sum(labelled)} of its {len(labelled)} steps; a recording "
                            "labels every step or none")
        ok, n = _first_success(e["term"])
        episodes.append(Episode(np.stack(e["obs"][:-1]), np.stack(e["actions"]),
                                np.asarray(e["rewards"], np.float64), ok, e["seed"], n,
                                np.asarray(e["term"], bool),
                                np.stack(e["labels"]) if all(labelled) else None, name))
    return meta, episodes, (None if complete or not cut else cut)


def _seed(ep):
    """An h5 json episode's seed (reset_kwargs' seed, or episode_seed), None if absent."""
    kw = ep.get("reset_kwargs")
    if kw is not None and not isinstance(kw, dict):
        raise ValueError(f"reset_kwargs is {type(kw).__name__}, not an object")
    seed = (kw or {}).get("seed", ep.get("episode_seed"))
    if isinstance(seed, list) and len(seed) >= 1:
        seed = seed[0]
    if seed is not None and not (_is_int(seed) and seed >= 0):
        raise ValueError(f"seed {seed!r} is not an integer >= 0")
    return seed


def _read_json(path, jpath):
    """The env_info and episodes of an h5's json, checked as ManiSkill writes them."""
    try:
        info = json.loads(read_regular(jpath, MAX_JSON_BYTES, "a trajectory .json"))
    except FileNotFoundError:
        raise DemoError(f"--demos {path}: its json ({jpath}) is missing; ManiSkill's "
                        "trajectory format keeps env and episode information there") from None
    except FileCheckError as e:
        raise DemoError(f"--demos {path}: its json: {e}") from None
    except OSError as e:
        raise DemoError(f"--demos {path}: its json {jpath} cannot be read ({e.strerror})") \
            from None
    except ValueError as e:
        raise DemoError(f"--demos {path}: its json {jpath} is damaged ({e})") from None
    bad = lambda why: DemoError(f"--demos {path}: its json {jpath}: {why}")  # noqa: E731
    if not isinstance(info, dict) or not isinstance(info.get("env_info"), dict):
        raise bad("no env_info object")
    env_info, listed = info["env_info"], info.get("episodes")
    kw = env_info.get("env_kwargs", {})
    if not isinstance(kw, dict):
        raise bad(f"env_info.env_kwargs is {json.dumps(kw)}, not an object (ManiSkill writes "
                  "the env's gym.make kwargs there)")
    if not isinstance(env_info.get("env_id"), str):
        raise bad("env_info.env_id is not a string")
    if not isinstance(listed, list) or not all(isinstance(e, dict) for e in listed):
        raise bad("episodes is not a list of objects")
    seen = {}
    for i, ep in enumerate(listed):
        k = ep.get("episode_id")
        if not (_is_int(k) and k >= 0):
            raise bad(f"episodes[{i}] has episode_id {k!r}, not an integer >= 0")
        if k in seen:
            raise bad(f"episodes[{seen[k]}] and episodes[{i}] both list episode_id {k}; each "
                      "episode is listed once (its steps would count twice)")
        seen[k] = i
        try:
            _seed(ep)
        except ValueError as e:
            raise bad(f"episodes[{i}] (episode_id {k}): {e}") from None
    return env_info, kw, listed


def _dataset(path, g, key, budget, name, ndim):
    """The numeric dataset ``g[key]`` of ``ndim`` dimensions as float64, its size taken from
    ``budget`` before it is read."""
    import h5py

    ds = g[key]
    if not isinstance(ds, h5py.Dataset) or ds.dtype.kind not in "biuf" or ds.ndim != ndim:
        raise DemoError(f"--demos {path}: {name}/{key} is not a {ndim}-dimensional numeric "
                        "dataset")
    budget.take(int(np.prod(ds.shape, dtype=np.int64)), f"{name}/{key} of shape {ds.shape}")
    return np.asarray(ds, np.float64)


def read_h5(path: str, size=None) -> tuple[dict, list[Episode], list[tuple[int, np.ndarray]]]:
    """(env info, episodes with observations, (seed, actions) of those without) of a
    ManiSkill trajectory file."""
    try:
        import h5py
    except ImportError:
        raise DemoError(f"--demos {path}: reading ManiSkill .h5 files needs `h5py` "
                        "(pip install h5py, or the extra mjskill[train])") from None
    jpath = os.path.splitext(path)[0] + ".json"
    env_info, kw, listed = _read_json(path, jpath)
    budget = _Budget(path, os.stat(path).st_size if size is None else size)
    episodes, to_replay = [], []
    try:
        with h5py.File(path, "r") as h:
            for ep in listed:
                name = f"traj_{ep['episode_id']}"
                if name not in h or not isinstance(h[name], h5py.Group):
                    raise DemoError(f"--demos {path}: the json lists {name}, which the file "
                                    "does not hold")
                g = h[name]
                if "actions" not in g:
                    raise DemoError(f"--demos {path}: {name} has no actions")
                act = _dataset(path, g, "actions", budget, name, 2)
                t = len(act)
                if t == 0 or act.shape[1] == 0:
                    raise DemoError(f"--demos {path}: {name} has actions of shape {act.shape}")
                lengths = {}
                succ = np.zeros(t, bool)
                if "success" in g:
                    succ = _dataset(path, g, "success", budget, name, 1) != 0
                    lengths["success flags"] = len(succ)
                rew = np.zeros(t)
                if "rewards" in g:
                    rew = _dataset(path, g, "rewards", budget, name, 1)
                    lengths["rewards"] = len(rew)
                for what, n in lengths.items():
                    if n != t:
                        raise DemoError(f"--demos {path}: {name} has {n} {what} for {t} "
                                        "actions (one per action)")
                seed = _seed(ep)
                obs = g.get("obs")
                if obs is None or not isinstance(obs, h5py.Dataset):
                    if succ.any() and seed is not None:
                        to_replay.append((seed, act, f"{name} (seed {seed})"))
                    else:
                        to_replay.append((None, None, name))  # counted as failed
                    continue
                obs = _dataset(path, g, "obs", budget, name, 2)
                if len(obs) != t + 1:
                    raise DemoError(f"--demos {path}: {name} has obs of shape {obs.shape} for "
                                    f"{t} actions (expected ({t + 1}, D), the state obs mode)")
                ok, n = _first_success(succ)
                episodes.append(Episode(obs[:-1], act, rew, ok, seed, n, succ, None,
                                        f"{name} (seed {seed})"))
    except DemoError:
        raise
    except Exception as e:  # noqa: BLE001 - h5py raises many kinds for a bad file
        raise DemoError(f"--demos {path}: a damaged or unreadable HDF5 file "
                        f"({type(e).__name__}: {e})") from None
    robot = kw.get("robot_uids")
    if isinstance(robot, list):
        robot = robot[0] if robot else None
    mode = kw.get("control_mode") or (listed[0].get("control_mode") if listed else None)
    meta = dict(env_id=env_info.get("env_id"), robot=robot, control_mode=mode,
                obs_mode=kw.get("obs_mode") or "none")
    return meta, episodes, to_replay


def _open_demo(path):
    """``path`` opened as training.files.open_regular opens it (a regular file of at most
    MAX_FILE_BYTES, never a FIFO or device), errors as DemoErrors naming the file."""
    try:
        f = open_regular(path, MAX_FILE_BYTES, "a recording .mcap or a ManiSkill "
                                               "trajectory .h5")
    except FileCheckError as e:
        raise DemoError(f"--demos {e}") from None
    except OSError as e:
        raise DemoError(f"--demos {path}: cannot read it ({e.strerror})") from None
    if os.fstat(f.fileno()).st_size == 0:
        f.close()
        raise DemoError(f"--demos {path}: the file is empty")
    return f


def _first_bad(x, low=None, high=None):
    """(index, value, why) of the first entry of ``x`` that is not finite, beyond float32's
    range, or outside [low, high] where given; None when every entry is fine."""
    ok = np.isfinite(x) & (np.abs(x) <= F32_MAX)
    if low is not None:
        # Compared in float32, as the env takes actions (a recording's text holds the
        # shortest decimal of each float32 value, a little off it in float64).
        with np.errstate(over="ignore", invalid="ignore"):
            x32 = x.astype(np.float32)
        ok &= (x32 >= low) & (x32 <= high)
    if ok.all():
        return None
    i = tuple(int(j) for j in np.argwhere(~ok)[0])
    v = float(x[i])
    if not np.isfinite(v):
        why = "is not finite"
    elif abs(v) > F32_MAX:
        why = f"is beyond float32's range (±{F32_MAX:.4g})"
    else:
        k = i[-1]
        why = (f"is outside the action space (entry {k}: {float(low[k]):g} .. "
               f"{float(high[k]):g})")
    return i, v, why


def _check_values(path, e, low=None, high=None):
    """Every observation, action, label and reward of episode ``e`` finite in float32, every
    action and label within [low, high] (the action space, as float32) where given, and the
    lengths consistent; DemoError naming the file, episode, step and value otherwise."""
    t = len(e.actions)
    if len(e.obs) != t or len(e.rewards) != t:
        raise DemoError(f"--demos {path}: {e.name} has {len(e.obs)} observations and "
                        f"{len(e.rewards)} rewards for {t} actions")
    if low is not None:
        low, high = (np.asarray(b, np.float32) for b in (low, high))
    for what, x, box in (("obs", e.obs, False), ("action", e.actions, True),
                         ("expert_action", e.labels, True), ("reward", e.rewards, False)):
        if x is None:
            continue
        bad = _first_bad(x, *((low, high) if box else ()))
        if bad is not None:
            (step, *entry), v, why = bad
            where = f"{what}[{entry[0]}]" if entry else what
            raise DemoError(f"--demos {path}: {e.name}, step {step}: {where} = {v!r} {why}; "
                            "the file is damaged or not one to learn from")


def mjskill_spaces(env_id, robot, control_mode):
    """(observation size, action low, action high) of mjskill's ``env_id`` with ``robot`` in
    ``control_mode``, state observations: one env made and closed (``load``'s ``spaces``)."""
    import gymnasium as gym

    import mjskill  # noqa: F401  (registers the envs)

    env = gym.make(f"mjskill/{env_id}", robot_uids=robot, control_mode=control_mode,
                   obs_mode="state")
    try:
        return env.observation_space.shape[0], env.action_space.low, env.action_space.high
    finally:
        env.close()


def load(paths, env_id: str | None, robot: str | None, control_mode: str | None,
         trainer: str = "ppo.py", keep_failed: bool = False, spaces=None) -> Demos:
    """Reads and checks every file; ``env_id``/``robot``/``control_mode`` None take the demos'
    own (``trainer`` names the script in the advice on control modes). Failed episodes are
    left out and counted (``skipped_failed``), or with ``keep_failed`` kept too (counted in
    ``kept_failed``): noise-injected demos label every visited state with the expert's
    action, whatever the episode's outcome. ``spaces(env_id, robot, control_mode)``, when
    given (:func:`mjskill_spaces`), returns the run's (observation size, action low, action
    high): the demos' sizes must match them and every action and label lie within the
    bounds."""
    if not paths:
        raise DemoError("--demos needs at least one file")
    demos = None
    seen = {}
    read = []  # (path, episode) of every episode read, kept or not
    replays = []  # (path, name, actions) of the episodes to replay
    for path in paths:
        with _open_demo(path) as f:
            st = os.fstat(f.fileno())
            if (st.st_dev, st.st_ino) in seen:
                raise DemoError(f"--demos {path}: the same file as {seen[st.st_dev, st.st_ino]}"
                                ", given twice; give each file once (its episodes would count "
                                "twice)")
            seen[st.st_dev, st.st_ino] = path
            head = f.read(8)
            f.seek(0)
            mcap = recording.MAGIC.startswith(head)
            if mcap:
                meta, eps, cut = read_mcap(path, f, st.st_size)
        command = None
        if mcap:
            to_replay = []
            command = meta.get("command")
            dim, act_dim = meta["obs_dim"], len(meta["act_low"])
            for e in eps:
                _check_values(path, e, meta["act_low"], meta["act_high"])
            m = dict(env_id=meta.get("env_id"), robot=meta.get("robot"),
                     control_mode=meta.get("control_mode"))
        elif head == b"\x89HDF\r\n\x1a\n":
            cut = None
            m, eps, to_replay = read_h5(path, st.st_size)
            if eps and m["obs_mode"] not in ("state", "state_dict"):
                raise DemoError(f"--demos {path}: observations recorded with obs_mode "
                                f"{m['obs_mode']!r}; training uses state observations")
            dim = eps[0].obs.shape[1] if eps else None
            acts = [e.actions for e in eps] + [a for _, a, _ in to_replay if a is not None]
            act_dim = acts[0].shape[1] if acts else None
            for e in eps:
                if e.obs.shape[1] != dim:
                    raise DemoError(f"--demos {path}: {e.name} has observations of "
                                    f"{e.obs.shape[1]} values, {eps[0].name} of {dim}")
                _check_values(path, e)
            for a in acts:
                if a.shape[1] != act_dim:
                    raise DemoError(f"--demos {path}: its episodes have actions of "
                                    f"{act_dim} and {a.shape[1]} values")
            for _, a, name in to_replay:
                if a is not None:
                    _check_actions(path, name, a)
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
        for what, mine, theirs in (("observations", dim, demos.obs_dim),
                                   ("actions", act_dim, demos.act_dim)):
            if mine is not None and theirs is not None and mine != theirs:
                raise DemoError(f"--demos {path}: {what} of {mine} values, the other files' "
                                f"have {theirs}")
        demos.obs_dim = demos.obs_dim or dim
        demos.act_dim = demos.act_dim or act_dim
        if cut:
            done = len(eps)
            demos.notes.append(f"--demos {path}: cut short ({cut}); its {done} finished "
                               f"episode{'s' if done != 1 else ''} are read, an unfinished "
                               "last one left out")
        for e in eps:
            read.append((path, e))
            if e.success or keep_failed:
                demos.episodes.append(e)
                demos.kept_failed += not e.success
            else:
                demos.skipped_failed += 1
        for seed, act, name in to_replay:
            if act is None:
                demos.skipped_failed += 1
            else:
                demos.to_replay.append((seed, act))
                replays.append((path, name, act))
        demos.files.append(path)
        if command:
            demos.commands.append(command)
    if spaces is not None:
        _check_spaces(demos, spaces, read, replays)
    if not demos.episodes and not demos.to_replay:
        raise DemoError(f"--demos {' '.join(paths)}: no successful episode "
                        f"({demos.skipped_failed} failed, none finished with success)")
    return demos


def _check_spaces(demos, spaces, read, replays):
    """The demos against the run's spaces (``load``'s ``spaces``): sizes, then every action
    and label within the action space."""
    what = f"{demos.env_id} with {demos.robot or 'its default robot'} in {demos.control_mode}"
    try:
        obs_dim, low, high = spaces(demos.env_id, demos.robot, demos.control_mode)
    except Exception as e:  # noqa: BLE001 - the env's errors for a bad id, robot or mode
        raise DemoError(f"--demos {' '.join(demos.files)}: cannot make {what} to check the "
                        f"demos against: {e}") from None
    files = " ".join(demos.files)
    if demos.obs_dim is not None and demos.obs_dim != obs_dim:
        raise DemoError(f"--demos {files}: observations of {demos.obs_dim} values, but {what} "
                        f"observes {obs_dim} (demos of another mjskill version or env "
                        "options?)")
    if demos.act_dim is not None and demos.act_dim != len(low):
        raise DemoError(f"--demos {files}: actions of {demos.act_dim} values, but {what} "
                        f"takes {len(low)}")
    for path, e in read:
        _check_values(path, e, low, high)
    for path, name, act in replays:
        _check_actions(path, name, act, low, high)


def _check_actions(path, name, act, low=None, high=None):
    """The actions ``act`` of the episode ``name`` (one without observations, to replay)
    finite in float32 and within [low, high] where given."""
    if low is not None:
        low, high = (np.asarray(b, np.float32) for b in (low, high))
    bad = _first_bad(act, low, high)
    if bad is not None:
        (step, k), v, why = bad
        raise DemoError(f"--demos {path}: {name}, step {step}: action[{k}] = {v!r} {why}; "
                        "the file is damaged or not one to learn from")


def fingerprints(paths):
    """What the files ``load`` reads for ``paths`` hold (each, and the ``.json`` beside an
    ``.h5``): training.files.fingerprint's absolute path, size and SHA-256, which a run's
    checkpoint records so that ``--resume`` can tell a file replaced since."""
    out = []
    for path in paths:
        with _open_demo(path) as f:
            h5 = f.read(8) == b"\x89HDF\r\n\x1a\n"
        out.append(fingerprint(path, MAX_FILE_BYTES))
        if h5:
            out.append(fingerprint(os.path.splitext(path)[0] + ".json", MAX_JSON_BYTES))
    return out


def check_unchanged(saved, run):
    """--resume ``run``: DemoError unless the files of ``saved`` (:func:`fingerprints`' at
    the run's start) hold what they held then."""
    changed = changed_since(saved, MAX_FILE_BYTES)
    if changed:
        raise DemoError(f"--resume {run}: the demo files changed since the run started ("
                        + "; ".join(changed) + "); the run's warm start and behaviour-cloning "
                        "term come from the files it started with: restore them, or start a "
                        "new run")


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
                                              np.asarray(su, bool), None,
                                              f"replayed episode (seed {seed})"))
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

"""Writes mjskill policy files: an MLP as an ONNX graph with the observation normalisation inside
and the metadata `mjskill eval --policy` reads (docs/training.md).

Needs only numpy and the `onnx` package (no torch): examples/ppo.py passes its trained weights,
examples/make_test_policy.py seeded random ones.

As a script it hides observation entries from an existing policy file: the graph then acts as
if those entries were 0, whatever they hold (examples/ppo.py trains that way from the start;
docs/training.md):

    python examples/policy_onnx.py hide IN.onnx OUT.onnx --obs 16,17

and gives a file another name of the same env (PickCubeSO100-v1 is PickCube-v1 with the SO100):

    python examples/policy_onnx.py retarget IN.onnx OUT.onnx --env-id PickCube-v1

and sets a least value for action components (again on a floored file: the new values replace
those of the same components, the others are kept):

    python examples/policy_onnx.py floor IN.onnx OUT.onnx --action 7:-0.545

and snaps action components to the action space's bounds at a threshold (the component
becomes its upper bound from the threshold on and its lower bound below it; the bounds are
read from the mjskill package):

    python examples/policy_onnx.py snap IN.onnx OUT.onnx --action 7:-0.75

and averages several files for the same env, robot and modes into one (an ensemble: each
member's graph runs on the same observation, its action clipped to the env's action space,
which this command reads from the mjskill package, and the file outputs the mean; the first
member's metadata is kept, and every member's training and demos commands are listed under
``ensemble_members``):

    python examples/policy_onnx.py ensemble OUT.onnx A.onnx B.onnx C.onnx

and bounds the controller target that an action component moves, while an observed vector is
short (the SO100's jaw target kept at −0.77 rad or more within 1 cm of the goal: a lighter
squeeze where PhysX reports a pinch as arm motion, docs/training.md). The target is an entry
of the flat state observation, named by its part and position; how far one unit of the
action moves it is measured in the mjskill env that the file names:

    python examples/policy_onnx.py ease IN.onnx OUT.onnx --action 5 \
        --target agent/controller/target_qpos:5 --least -0.77 --near extra/obj_to_goal_pos:0.01

Every edit reads a regular file only (a FIFO or device is refused, never read), refuses a file
whose metadata names a key twice, and writes OUT beside itself under a short temporary name
(``.mjskill-PID-XXXXXXXX.tmp``, created exclusively, never through a link), renamed into
place once complete, with the mode of the file it replaces: OUT may be IN, and a failed
write (a full disk) leaves it as it was. OUT may not be a symbolic link (refused, naming its
target): the rename would replace the link rather than edit the file it points to, so give
the target itself.

The graph: input ``obs`` (float32, [batch, obs_dim]); ``x = clip((obs - mean) / std, -clip,
clip)``; then for every layer ``x = x @ W + b``, with ``tanh`` between layers (not after the
last); output ``action`` (float32, [batch, act_dim]), the mean action. With a residual (a
network trained on targets relative to measured joint positions, examples/imitate.py
--relative-labels), chosen raw observation entries are added to chosen action entries:
``action[k] = x[k] + obs[residual[k]]``.
"""

from __future__ import annotations

import json
import os
import stat
import sys

import numpy as np

# examples/ holds the shared training package (also when this file is run as a script).
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from training.files import atomic_write  # noqa: E402, F401 (atomic_write: the trainers')

#: The metadata_props every policy file carries (docs/training.md).
METADATA_KEYS = ("env_id", "robot_uids", "control_mode", "obs_mode", "training_command")

#: ONNX opset and IR version: old enough for tract and onnxruntime 1.1x alike.
OPSET = 17
IR_VERSION = 8


def mlp_forward(obs, layers, obs_mean, obs_std, obs_clip, residual=None):
    """The graph's computation in numpy (float64): the reference the tests compare against."""
    raw = np.asarray(obs, np.float64)
    x = (raw - obs_mean) / obs_std
    if obs_clip is not None:
        x = np.clip(x, -obs_clip, obs_clip)
    for k, (w, b) in enumerate(layers):
        x = x @ np.asarray(w, np.float64) + np.asarray(b, np.float64)
        if k + 1 < len(layers):
            x = np.tanh(x)
    for k, i in enumerate(residual or ()):
        if i is not None:
            x[..., k] += raw[..., i]
    return x


def check_residual(residual, obs_dim, act_dim):
    """``residual`` (one entry per action entry: an observation index or None) as a list;
    ValueError for another length or an index out of range."""
    residual = list(residual)
    if len(residual) != act_dim:
        raise ValueError(f"residual has {len(residual)} entries for {act_dim} action entries")
    bad = [i for i in residual if i is not None and not 0 <= int(i) < obs_dim]
    if bad:
        raise ValueError(f"residual observation indices {bad} out of range 0..{obs_dim - 1}")
    return [None if i is None else int(i) for i in residual]


def write_mlp_policy(path, layers, obs_mean, obs_std, metadata, obs_clip=None, residual=None):
    """Writes the MLP ``layers`` (a list of (W [in, out], b [out]) arrays) with the observation
    normalisation ``(obs - obs_mean) / obs_std`` (clipped to ±obs_clip unless None) as an ONNX
    policy file at ``path``, with ``metadata`` (a dict of str) as its metadata_props: it must
    hold METADATA_KEYS. ``residual`` (optional, one entry per action entry: an observation
    index or None) adds that raw observation entry to the action entry (``Gather``, then
    ``Where`` where only some entries take one, and ``Add``: exact, no multiplication).
    Returns the ModelProto."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    missing = [k for k in METADATA_KEYS if k not in metadata]
    if missing:
        raise ValueError(f"metadata lacks {missing}; a policy file carries {list(METADATA_KEYS)}")
    obs_mean = np.asarray(obs_mean, np.float32)
    obs_std = np.asarray(obs_std, np.float32)
    obs_dim = obs_mean.shape[0]
    if obs_std.shape != (obs_dim,) or not np.all(obs_std > 0):
        raise ValueError("obs_std must be positive, one value per observation")
    if np.asarray(layers[0][0]).shape[0] != obs_dim:
        raise ValueError(
            f"the first layer takes {np.asarray(layers[0][0]).shape[0]} values, the "
            f"normalisation {obs_dim}"
        )
    act_dim = np.asarray(layers[-1][1]).shape[0]
    inits = [
        numpy_helper.from_array(obs_mean, "obs_mean"),
        numpy_helper.from_array(obs_std, "obs_std"),
    ]
    nodes = [
        helper.make_node("Sub", ["obs", "obs_mean"], ["obs_centred"]),
        helper.make_node("Div", ["obs_centred", "obs_std"], ["obs_norm"]),
    ]
    x = "obs_norm"
    if obs_clip is not None:
        inits += [
            numpy_helper.from_array(np.array(-obs_clip, np.float32), "obs_clip_lo"),
            numpy_helper.from_array(np.array(obs_clip, np.float32), "obs_clip_hi"),
        ]
        nodes.append(helper.make_node("Clip", [x, "obs_clip_lo", "obs_clip_hi"], ["obs_clipped"]))
        x = "obs_clipped"
    for k, (w, b) in enumerate(layers):
        w = np.asarray(w, np.float32)
        b = np.asarray(b, np.float32)
        inits += [numpy_helper.from_array(w, f"w{k}"), numpy_helper.from_array(b, f"b{k}")]
        last = k + 1 == len(layers)
        nodes.append(helper.make_node("MatMul", [x, f"w{k}"], [f"mm{k}"]))
        out = "action" if last and residual is None else f"lin{k}"
        nodes.append(helper.make_node("Add", [f"mm{k}", f"b{k}"], [out]))
        if not last:
            nodes.append(helper.make_node("Tanh", [out], [f"h{k}"]))
            x = f"h{k}"
    if residual is not None:
        residual = check_residual(residual, obs_dim, act_dim)
        idx = np.array([0 if i is None else i for i in residual], np.int64)
        inits.append(numpy_helper.from_array(idx, "residual_obs"))
        nodes.append(helper.make_node("Gather", ["obs", "residual_obs"], ["residual_all"],
                                      axis=-1))
        added = "residual_all"
        if any(i is None for i in residual):
            keep = np.array([i is not None for i in residual])
            inits += [numpy_helper.from_array(keep, "residual_keep"),
                      numpy_helper.from_array(np.array(0.0, np.float32), "residual_none")]
            nodes.append(helper.make_node("Where", ["residual_keep", "residual_all",
                                                    "residual_none"], ["residual"]))
            added = "residual"
        nodes.append(helper.make_node("Add", [f"lin{len(layers) - 1}", added], ["action"]))
    graph = helper.make_graph(
        nodes,
        "mjskill_policy",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", obs_dim])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", act_dim])],
        initializer=inits,
    )
    model = helper.make_model(
        graph,
        opset_imports=[helper.make_opsetid("", OPSET)],
        producer_name="mjskill",
        doc_string="mjskill policy: observation in, mean action out (docs/training.md)",
    )
    model.ir_version = IR_VERSION
    helper.set_model_props(model, {k: str(v) for k, v in metadata.items()})
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return model


def save_weights_json(path, layers, obs_mean, obs_std, obs_clip):
    """Writes the weights as JSON (for a reference computation in another language)."""
    with open(path, "w") as f:
        json.dump(
            {
                "obs_mean": np.asarray(obs_mean, np.float32).tolist(),
                "obs_std": np.asarray(obs_std, np.float32).tolist(),
                "obs_clip": obs_clip,
                "activation": "tanh",
                "layers": [
                    {
                        "w": np.asarray(w, np.float32).tolist(),
                        "b": np.asarray(b, np.float32).tolist(),
                    }
                    for w, b in layers
                ],
            },
            f,
        )


def parse_floor(text, value="LEAST", example="7:-0.545", meaning="least value"):
    """``INDEX:LEAST`` (e.g. ``7:-0.545``) as (index, least): an index >= 0 and a finite
    least value that float32 holds (the file stores float32). ValueError otherwise, naming
    the text and the form expected. ``value``, ``example`` and ``meaning`` name the number in
    the messages (``snap`` reads ``INDEX:THRESHOLD`` the same way)."""
    parts = str(text).split(":")
    form = f"{text!r}: expected INDEX:{value}, e.g. {example}"
    if len(parts) != 2:
        raise ValueError(form)
    try:
        k, v = int(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(form) from None
    check_floor(k, v, repr(str(text)), meaning)
    return k, v


def check_floor(k, v, what=None, meaning="least value"):
    """ValueError unless ``k`` is an action index >= 0 and ``v`` a finite least value (or
    other ``meaning``) within float32's range; ``what`` names them in the message (default
    ``k:v``)."""
    what = what or f"{k}:{v}"
    if k < 0:
        raise ValueError(f"{what}: the action index {k} is negative")
    f32 = float(np.finfo(np.float32).max)
    if not np.isfinite(v) or abs(v) > f32:
        raise ValueError(f"{what}: the {meaning} must be a finite number within "
                         f"float32's range (±{f32:.4g})")


def parse_floors(texts, value="LEAST", example="7:-0.545", meaning="least value",
                 what="floor"):
    """A list of ``INDEX:LEAST`` as a dict index -> least; an index given twice is a
    ValueError (even with the same value: one floor per component). The other arguments
    name the number as :func:`parse_floor` does, and ``what`` the edit."""
    floors = {}
    for t in texts:
        k, v = parse_floor(t, value, example, meaning)
        if k in floors:
            raise ValueError(f"action index {k} is given twice ({k}:{floors[k]:g} and {t}); "
                             f"give each component one {what}")
        floors[k] = v
    return floors


def load_policy(path):
    """Reads the ONNX file ``path``: a regular file only (a FIFO, device or directory is
    refused, never read, so nothing hangs), whose metadata names each key once (runtimes
    would take either value of a duplicated key: mjskill refuses such a file, and an edit
    must not merge it into one it accepts). Returns the ModelProto."""
    import onnx

    fd = os.open(str(path), os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = ("a directory" if stat.S_ISDIR(st.st_mode) else "a FIFO"
                    if stat.S_ISFIFO(st.st_mode) else "a device or socket")
            raise ValueError(f"{path} is {kind}, not a regular file; a policy file is one")
        with os.fdopen(fd, "rb") as f:
            fd = None
            data = f.read()
    finally:
        if fd is not None:
            os.close(fd)
    model = onnx.load_model_from_string(data)
    seen = set()
    for p in model.metadata_props:
        if p.key in seen:
            raise ValueError(f"{path}: its metadata_props has the key {p.key!r} more than once; "
                             "each key may appear once (mjskill refuses such a file)")
        seen.add(p.key)
    return model


def save_atomic(model, dst):
    """Writes ``model`` to ``dst`` through a temporary file beside it
    (training.files.atomic_write: created exclusively, never through a link, with the mode
    of the file it replaces): a failed write leaves ``dst`` as it was, even when it is the
    file the model was read from. A symbolic link as ``dst`` is refused (ValueError): the
    rename would replace the link, not edit its target."""
    import onnx

    atomic_write(str(dst), lambda t: onnx.save(model, t))


def save_derived(model, dst, note, **props):
    """Saves ``model`` as ``dst`` (atomically, :func:`save_atomic`) with its metadata
    updated by ``props`` and ``note`` appended to ``derived`` (how the file was edited after
    training), after onnx's checker. A metadata key given twice is a ValueError."""
    import onnx

    meta = {}
    for p in model.metadata_props:
        if p.key in meta:
            raise ValueError(f"its metadata_props has the key {p.key!r} more than once; each "
                             "key may appear once (mjskill refuses such a file)")
        meta[p.key] = p.value
    meta.update(props)
    meta["derived"] = "; ".join(x for x in (meta.get("derived", ""), note) if x)
    del model.metadata_props[:]
    onnx.helper.set_model_props(model, meta)
    onnx.checker.check_model(model)
    save_atomic(model, dst)
    return model


def hide_obs(src, dst, indices, note):
    """Writes ``src`` as ``dst`` with the observation entries ``indices`` hidden: their rows of
    the first layer become zero and their contribution at observation 0 (after normalisation
    and clipping) moves into the first bias, so the new graph gives, for any observation, the
    action the old one gives with those entries set to 0. Records ``hidden_obs`` and the
    ``note`` (appended to ``derived``) in the metadata. Returns the ModelProto."""
    import onnx
    from onnx import numpy_helper

    model = load_policy(src)
    graph = model.graph
    init = {t.name: t for t in graph.initializer}
    names = {"obs_mean", "obs_std", "w0", "b0"}
    if not names <= set(init):
        raise ValueError(f"{src} is not an mjskill MLP policy file (needs {sorted(names)})")
    get = lambda n: numpy_helper.to_array(init[n]).astype(np.float64)  # noqa: E731
    mean, std, w0, b0 = get("obs_mean"), get("obs_std"), get("w0"), get("b0")
    idx = sorted(set(int(i) for i in indices))
    bad = [i for i in idx if not 0 <= i < mean.shape[0]]
    if bad:
        raise ValueError(f"observation indices {bad} out of range 0..{mean.shape[0] - 1}")
    x0 = (0.0 - mean[idx]) / std[idx]
    if "obs_clip_hi" in init:
        x0 = np.clip(x0, get("obs_clip_lo"), get("obs_clip_hi"))
    b0 = b0 + x0 @ w0[idx]
    w0[idx] = 0.0
    for name, value in (("w0", w0), ("b0", b0)):
        init[name].CopyFrom(numpy_helper.from_array(value.astype(np.float32), name))
    props = {p.key: p.value for p in model.metadata_props}
    old = [int(i) for i in props.get("hidden_obs", "").split(",") if i]
    hidden = ",".join(str(i) for i in sorted(set(old + idx)))
    return save_derived(model, dst, note, hidden_obs=hidden)


def retarget(src, dst, env_id, note):
    """Writes ``src`` as ``dst`` for another env id, the graph unchanged: for envs that are
    the same task under two names (ManiSkill's PickCubeSO100-v1 is PickCube-v1 with
    ``robot_uids="so100"``, PickCubeWidowXAI-v1 the same with ``"widowxai"``). Records the
    ``note`` (appended to ``derived``). Returns the ModelProto."""
    return save_derived(load_policy(src), dst, note, env_id=env_id)


def floor_actions(src, dst, floors, note):
    """Writes ``src`` as ``dst`` with a lower bound on some action components: ``floors``
    maps an action index to its least value (the others are left as they are), applied to
    the graph's output with ``Max``. On a file floored before (``action_floor``, as this
    function and examples/ppo.py --action-floor write it), the given components get the new
    values and the others keep theirs. Least values must be finite and within float32's
    range (a NaN floor would be run differently by tract and onnxruntime). Records the
    ``note`` (appended to ``derived``). Returns the ModelProto."""
    from onnx import helper, numpy_helper

    for k, v in floors.items():
        check_floor(int(k), float(v))  # the command line's rule
    model = load_policy(src)
    g = model.graph
    out = g.output[0]
    act_dim = out.type.tensor_type.shape.dim[-1].dim_value
    if any(not 0 <= k < act_dim for k in floors):
        raise ValueError(f"action indices {sorted(floors)} out of range 0..{act_dim - 1}")
    init = {t.name: t for t in g.initializer}
    floored = "action_floor" in init and any(
        n.op_type == "Max" and "action_floor" in n.input and out.name in n.output
        for n in g.node)
    if "action_floor" in init and not floored:
        raise ValueError(f"{src} has an initializer named action_floor that is not the "
                         "output's floor; cannot floor it")
    if floored:
        lo = numpy_helper.to_array(init["action_floor"]).astype(np.float32).copy()
    else:
        lo = np.full(act_dim, np.finfo(np.float32).min, np.float32)
    for k, v in floors.items():
        lo[k] = v
    if floored:
        init["action_floor"].CopyFrom(numpy_helper.from_array(lo, "action_floor"))
    else:
        old = out.name
        raw = old + "_unfloored"
        for node in g.node:
            node.output[:] = [raw if o == old else o for o in node.output]
        g.initializer.append(numpy_helper.from_array(lo, "action_floor"))
        g.node.append(helper.make_node("Max", [raw, "action_floor"], [old]))
    return save_derived(model, dst, note)


def load_unedited(src, key, verb, done):
    """Reads the policy file ``src`` for an edit that records ``key`` in its metadata; a file
    that carries it already (edited that way before) is a ValueError."""
    model = load_policy(src)
    meta = {p.key: p.value for p in model.metadata_props}
    if key in meta:
        raise ValueError(f"{src} is {done} already ({key} {meta[key]}); {verb} the file it was "
                         "made from")
    return model


def snap_actions(src, dst, thresholds, note, low, high):
    """Writes ``src`` as ``dst`` with some action components snapped to their bounds:
    ``thresholds`` maps an action index to a threshold, and that component becomes
    ``high[index]`` where the graph's output reaches the threshold and ``low[index]`` below
    it (``Less`` and ``Where`` on the output; the other components are left as they are).
    For a gripper a clone drives through partial openings, each of which feeds the next
    observation: snapped, the first sign of opening opens it fully (docs/training.md). The
    bounds ``low`` and ``high`` are the action space's (:func:`action_bounds`); a component
    without finite bounds cannot be snapped. A file snapped before is refused. Records
    ``action_snap`` (JSON: index -> threshold, low, high) and the ``note`` (appended to
    ``derived``). Returns the ModelProto."""
    from onnx import helper, numpy_helper

    model = load_unedited(src, "action_snap", "snap", "snapped")
    g = model.graph
    out = g.output[0]
    act_dim = out.type.tensor_type.shape.dim[-1].dim_value
    low = np.asarray(low, np.float32)
    high = np.asarray(high, np.float32)
    if low.shape != (act_dim,) or high.shape != (act_dim,):
        raise ValueError(f"the action bounds have {low.size} and {high.size} entries; "
                         f"{src} acts with {act_dim}")
    if not thresholds:
        raise ValueError("no action component to snap")
    for k, t in thresholds.items():
        check_floor(int(k), float(t), f"{k}:{t}", "threshold")
        if not k < act_dim:
            raise ValueError(f"action index {k} out of range 0..{act_dim - 1}")
        if not (np.isfinite(low[k]) and np.isfinite(high[k])
                and abs(low[k]) < np.finfo(np.float32).max
                and abs(high[k]) < np.finfo(np.float32).max):
            raise ValueError(f"action component {k} is unbounded ({low[k]:g} to {high[k]:g}): "
                             "only a component with finite bounds can be snapped")
    mask = np.zeros(act_dim, bool)
    thr = np.zeros(act_dim, np.float32)
    for k, t in thresholds.items():
        mask[k] = True
        thr[k] = t
    old = out.name
    raw = old + "_unsnapped"
    for node in g.node:
        node.output[:] = [raw if o == old else o for o in node.output]
    # The unsnapped components' bounds are not read (and may be infinite, which a policy
    # file's constants may not be): zeros in their place.
    g.initializer.extend([
        numpy_helper.from_array(thr, "snap_threshold"),
        numpy_helper.from_array(np.where(mask, low, 0).astype(np.float32), "snap_low"),
        numpy_helper.from_array(np.where(mask, high, 0).astype(np.float32), "snap_high"),
        numpy_helper.from_array(mask, "snap_mask"),
    ])
    g.node.extend([
        helper.make_node("Less", [raw, "snap_threshold"], ["snap_below"]),
        helper.make_node("Where", ["snap_below", "snap_low", "snap_high"], ["snap_bound"]),
        helper.make_node("Where", ["snap_mask", "snap_bound", raw], [old]),
    ])
    record = {str(k): {"threshold": float(np.float32(t)), "low": float(low[k]),
                       "high": float(high[k])} for k, t in sorted(thresholds.items())}
    return save_derived(model, dst, note, action_snap=json.dumps(record))


def action_bounds(src):
    """The action space's bounds of the env that the policy file ``src`` names (mjskill's
    gymnasium env, so the mjskill package must be installed)."""
    env = _make_env({p.key: p.value for p in load_policy(src).metadata_props})
    try:
        space = env.action_space
        return (np.asarray(space.low, np.float32), np.asarray(space.high, np.float32))
    finally:
        env.close()


def _make_env(meta):
    import gymnasium as gym
    import mjskill  # noqa: F401  (registers the mjskill/ envs)

    return gym.make(f"mjskill/{meta['env_id']}", robot_uids=meta["robot_uids"],
                    control_mode=meta["control_mode"], obs_mode=meta["obs_mode"])


def observed_part(layout, name):
    """The flat (start, end) of the state observation's part ``name`` in ``layout``
    (``{name: (start, end)}``); an unknown name is a ValueError naming the valid ones."""
    if name not in layout:
        raise ValueError(f"the state observation has no part {name!r}; valid: "
                         + ", ".join(layout))
    return layout[name]


def observed_entry(layout, text):
    """``NAME:K``, entry K of the state observation's part NAME, as a flat index."""
    name, _, k = text.rpartition(":")
    try:
        start, end = observed_part(layout, name)
    except ValueError as e:
        raise ValueError(f"{text!r}: {e}") from None
    try:
        k = int(k)
    except ValueError:
        raise ValueError(f"{text!r}: expected NAME:K with K an integer, e.g. "
                         "agent/controller/target_qpos:5") from None
    if not 0 <= k < end - start:
        raise ValueError(f"{text!r}: {name} has {end - start} entries (0..{end - start - 1})")
    return start + k


def ease_probe(src, action, target, near):
    """What ``ease`` reads from the mjskill env that the policy file ``src`` names (so the
    mjskill package must be installed): the flat index of the observed target ``target``
    (``NAME:K``), the flat (start, end) of the vector ``near`` (a part's name), and how far one
    unit of action component ``action`` moves the target, measured: from a reset (seed 0), a
    step of +1 on that component and then one of +0.5, the others 0. The second move must be
    half the first (a target that the action moves by a fixed scale, such as a target-delta
    controller's) and the first not zero. A file whose obs mode is not ``state``, an unknown
    part or entry and an action that does not move the target are ValueErrors."""
    meta = {p.key: p.value for p in load_policy(src).metadata_props}
    if meta.get("obs_mode") != "state":
        raise ValueError(f"{src} acts on obs_mode {meta.get('obs_mode')!r}; only a file that "
                         "reads the flat 'state' observation can be eased")
    env = _make_env(meta)
    try:
        layout = {name: (a, b) for name, a, b in env.unwrapped._layout.parts}
        index = observed_entry(layout, target)
        span = observed_part(layout, near)
        n = env.action_space.shape[0]
        if not 0 <= action < n:
            raise ValueError(f"action index {action} out of range 0..{n - 1}")
        obs, _ = env.reset(seed=0)
        moves = []
        for u in (1.0, 0.5):
            a = np.zeros(n, np.float32)
            a[action] = u
            nxt = env.step(a)[0]
            moves.append(float(nxt[index]) - float(obs[index]))
            obs = nxt
    finally:
        env.close()
    first, second = moves
    if abs(first) < 1e-6 or abs(second - 0.5 * first) > 1e-5 * max(1.0, abs(first)):
        raise ValueError(f"action {action} does not move observation entry {index} by a "
                         f"fixed scale (+1 moved it {first:g}, then +0.5 {second:g}); ease "
                         "bounds a target that the action moves, such as a target-delta "
                         "controller's (agent/controller/target_qpos)")
    return index, span, first


def ease_actions(src, dst, note, action, target, scale, bound, near, radius, most=False,
                 names=None):
    """Writes ``src`` as ``dst`` with action component ``action`` limited so that the target
    it moves stays at or above ``bound`` (at or below it with ``most``) while the observed
    vector ``near`` (flat indices start, end) is shorter than ``radius``: the target after the
    step is ``obs[target] + scale · a``, so the component is raised (or lowered) to
    ``(bound − obs[target]) / scale`` where it would pass the bound (``MatMul``, ``Max`` or
    ``Min``, ``Less`` and ``Where`` on the output; elsewhere and for the other components the
    graph's action is kept). A file eased before is refused. Records ``action_ease`` (JSON,
    with ``names``, the target's and the vector's names, where given) and the ``note``
    (appended to ``derived``). Returns the ModelProto."""
    from onnx import helper, numpy_helper

    model = load_unedited(src, "action_ease", "ease", "eased")
    g = model.graph
    obs_dim = g.input[0].type.tensor_type.shape.dim[-1].dim_value
    act_dim = g.output[0].type.tensor_type.shape.dim[-1].dim_value
    start, end = near
    if not 0 <= action < act_dim:
        raise ValueError(f"action index {action} out of range 0..{act_dim - 1}")
    if not 0 <= target < obs_dim or not 0 <= start < end <= obs_dim:
        raise ValueError(f"observation entries {target} and {start}..{end} must lie in "
                         f"0..{obs_dim - 1}")
    for label, v in (("bound", bound), ("radius", radius), ("scale", scale)):
        if not np.isfinite(v) or abs(v) >= np.finfo(np.float32).max:
            raise ValueError(f"the {label} must be a finite float32, not {v!r}")
    if not radius > 0 or scale == 0:
        raise ValueError(f"the radius must be positive ({radius:g}) and the scale not zero")
    # The limit on the action: (bound - obs[target]) / scale, for every component (only
    # `action`'s is used).
    c = np.zeros((obs_dim, act_dim), np.float32)
    c[target, action] = -1.0 / scale
    b = np.zeros(act_dim, np.float32)
    b[action] = bound / scale
    # Raising the action raises the target where scale > 0: a least bound is a floor on it.
    op = "Max" if (scale > 0) != most else "Min"
    s = np.zeros((obs_dim, 1), np.float32)
    s[start:end, 0] = 1.0
    mask = np.zeros(act_dim, bool)
    mask[action] = True
    out = g.output[0].name
    raw = out + "_uneased"
    inp = g.input[0].name
    for node in g.node:
        node.output[:] = [raw if o == out else o for o in node.output]
    g.initializer.extend([
        numpy_helper.from_array(c, "ease_c"),
        numpy_helper.from_array(b, "ease_b"),
        numpy_helper.from_array(s, "ease_near"),
        numpy_helper.from_array(np.array([radius * radius], np.float32), "ease_r2"),
        numpy_helper.from_array(mask, "ease_mask"),
    ])
    g.node.extend([
        helper.make_node("MatMul", [inp, "ease_c"], ["ease_cx"]),
        helper.make_node("Add", ["ease_cx", "ease_b"], ["ease_limit"]),
        helper.make_node(op, [raw, "ease_limit"], ["ease_bounded"]),
        helper.make_node("Mul", [inp, inp], ["ease_sq"]),
        helper.make_node("MatMul", ["ease_sq", "ease_near"], ["ease_d2"]),
        helper.make_node("Less", ["ease_d2", "ease_r2"], ["ease_close"]),
        helper.make_node("And", ["ease_close", "ease_mask"], ["ease_use"]),
        helper.make_node("Where", ["ease_use", "ease_bounded", raw], [out]),
    ])
    record = {"action": action, "target": target, "scale": float(np.float32(scale)),
              ("most" if most else "least"): float(np.float32(bound)),
              "near": [start, end], "radius": float(np.float32(radius))}
    if names is not None:
        record["target_name"], record["near_name"] = names
    return save_derived(model, dst, note, action_ease=json.dumps(record))


#: The metadata that members of an ensemble must share.
ENSEMBLE_KEYS = ("env_id", "robot_uids", "control_mode", "obs_mode")


def ensemble(srcs, dst, note, low=None, high=None):
    """Writes ``dst``, the mean of the policy files ``srcs`` (at least two, the same
    ``ENSEMBLE_KEYS`` and input and output sizes): every member's nodes and initializers,
    renamed ``m<i>_...``, read the one input, and their outputs, each clipped to the action
    bounds ``low`` and ``high`` where given (as a runtime clips a single file's), are summed
    and scaled by 1/N. The metadata is the first member's, with ``ensemble_members`` (a JSON
    list of each member's ``training_command``, ``demos_command``, ``hidden_obs``, ``epochs``
    and ``eval_success``), ``hidden_obs`` the entries no member reads, ``env_steps`` those of
    the members' distinct demos, and the ``note`` appended to ``derived``. Returns the
    ModelProto."""
    import onnx
    from onnx import helper, numpy_helper

    if len(srcs) < 2:
        raise ValueError(f"an ensemble needs at least two policy files, got {len(srcs)}")
    models = [load_policy(s) for s in srcs]
    metas = [{p.key: p.value for p in m.metadata_props} for m in models]
    for src, meta in zip(srcs, metas):
        missing = [k for k in METADATA_KEYS if k not in meta]
        if missing:
            raise ValueError(f"{src} lacks the metadata_props {', '.join(missing)}")
        for k in ENSEMBLE_KEYS:
            if meta[k] != metas[0][k]:
                raise ValueError(f"{src} has {k} {meta[k]!r}, {srcs[0]} {metas[0][k]!r}: the "
                                 "members of an ensemble share their env, robot and modes")

    def dims(vi):
        return [d.dim_value or d.dim_param for d in vi.type.tensor_type.shape.dim]

    first = models[0].graph
    for src, m in zip(srcs, models):
        if len(m.graph.input) != 1 or len(m.graph.output) != 1:
            raise ValueError(f"{src}: a policy file has one input and one output")
        for a, b, what in ((m.graph.input[0], first.input[0], "input"),
                           (m.graph.output[0], first.output[0], "output")):
            if dims(a)[-1] != dims(b)[-1]:
                raise ValueError(f"{src}: its {what} has {dims(a)[-1]} values, {srcs[0]}'s "
                                 f"{dims(b)[-1]}")
    inp = first.input[0].name
    nodes, inits, outs = [], [], []
    # An unbounded entry (a continuous joint's target) gets float32's largest magnitude:
    # policy files hold finite constants only.
    big = np.finfo(np.float32).max
    for i, m in enumerate(models):
        g = m.graph
        own_in = g.input[0].name

        def rename(name, i=i, own_in=own_in):
            if name == "":
                return name
            return inp if name == own_in else f"m{i}_{name}"

        for t in g.initializer:
            t2 = onnx.TensorProto()
            t2.CopyFrom(t)
            t2.name = rename(t.name)
            inits.append(t2)
        for n in g.node:
            n2 = onnx.NodeProto()
            n2.CopyFrom(n)
            n2.input[:] = [rename(x) for x in n.input]
            n2.output[:] = [rename(x) for x in n.output]
            n2.name = rename(n.name) if n.name else f"m{i}_node{len(nodes)}"
            nodes.append(n2)
        out = rename(g.output[0].name)
        if low is not None:
            for bound, op in ((low, "Max"), (high, "Min")):
                name = f"m{i}_bound_{op.lower()}"
                finite = np.clip(np.asarray(bound, np.float64), -big, big).astype(np.float32)
                inits.append(numpy_helper.from_array(finite, name))
                nodes.append(helper.make_node(op, [out, name], [out + "_" + op.lower()],
                                              name=f"m{i}_clip_{op.lower()}"))
                out = out + "_" + op.lower()
        outs.append(out)
    total = outs[0]
    for k, o in enumerate(outs[1:], 1):
        nxt = f"ensemble_sum{k}"
        nodes.append(helper.make_node("Add", [total, o], [nxt], name=f"ensemble_add{k}"))
        total = nxt
    out_name = first.output[0].name
    inits.append(numpy_helper.from_array(np.array(1.0 / len(models), np.float32),
                                         "ensemble_scale"))
    nodes.append(helper.make_node("Mul", [total, "ensemble_scale"], [out_name],
                                  name="ensemble_mean"))
    graph = helper.make_graph(nodes, "mjskill_policy_ensemble", [first.input[0]],
                              [first.output[0]], inits)
    model = helper.make_model(graph, opset_imports=list(models[0].opset_import))
    model.ir_version = models[0].ir_version
    keys = ("training_command", "demos_command", "hidden_obs", "epochs", "eval_success")
    members = [{k: meta[k] for k in keys if k in meta} for meta in metas]
    props = dict(metas[0])
    # What no member reads; the members' own figures are listed per member.
    hidden = [{int(i) for i in meta.get("hidden_obs", "").split(",") if i} for meta in metas]
    props["hidden_obs"] = ",".join(str(i) for i in sorted(set.intersection(*hidden)))
    for k in ("epochs", "eval_success"):
        props.pop(k, None)
    # The env steps of the members' distinct demos.
    distinct = {meta.get("demos", src): int(meta.get("env_steps", 0) or 0)
                for src, meta in zip(srcs, metas)}
    props["env_steps"] = str(sum(distinct.values()))
    if "algorithm" in props:
        props["algorithm"] += f"; the mean of {len(models)} such files (ensemble_members)"
    onnx.helper.set_model_props(model, props)
    return save_derived(model, dst, note, ensemble_members=json.dumps(members))


def main(argv=None):
    import argparse

    p = argparse.ArgumentParser(description="Edits mjskill policy files.")
    sub = p.add_subparsers(dest="command", required=True)
    h = sub.add_parser("hide", help="hide observation entries (the graph reads them as 0)")
    h.add_argument("src")
    h.add_argument("dst")
    h.add_argument("--obs", required=True, help="comma-separated flat observation indices")
    h.add_argument("--note", default=None, help="text for the `derived` metadata")
    r = sub.add_parser("retarget", help="the same graph for another name of the same env")
    r.add_argument("src")
    r.add_argument("dst")
    r.add_argument("--env-id", required=True)
    r.add_argument("--note", default=None, help="text for the `derived` metadata")
    f = sub.add_parser("floor", help="a lower bound on action components")
    f.add_argument("src")
    f.add_argument("dst")
    f.add_argument("--action", required=True, action="append",
                   help="INDEX:LEAST, e.g. 7:-0.545 (repeatable)")
    f.add_argument("--note", default=None, help="text for the `derived` metadata")
    sn = sub.add_parser("snap", help="action components snapped to their bounds at a threshold")
    sn.add_argument("src")
    sn.add_argument("dst")
    sn.add_argument("--action", required=True, action="append",
                    help="INDEX:THRESHOLD, e.g. 7:-0.75 (repeatable): the component becomes "
                         "its upper bound from the threshold on, its lower bound below it")
    sn.add_argument("--note", default=None, help="text for the `derived` metadata")
    ea = sub.add_parser("ease", help="bound the controller target an action component "
                        "moves, while an observed vector is short (a lighter squeeze near the "
                        "goal)")
    ea.add_argument("src")
    ea.add_argument("dst")
    ea.add_argument("--action", type=int, required=True, help="the action component's index")
    ea.add_argument("--target", required=True,
                    help="NAME:K, the observed target the component moves: entry K of the "
                         "state observation's part NAME, e.g. agent/controller/target_qpos:5")
    eb = ea.add_mutually_exclusive_group(required=True)
    eb.add_argument("--least", type=float, help="the least value the target may take")
    eb.add_argument("--most", type=float, help="the most it may take")
    ea.add_argument("--near", required=True,
                    help="NAME:RADIUS: only while the state observation's part NAME (a vector, "
                         "e.g. extra/obj_to_goal_pos) is shorter than RADIUS")
    ea.add_argument("--note", default=None, help="text for the `derived` metadata")
    e = sub.add_parser("ensemble", help="the mean of several files' actions, as one file")
    e.add_argument("dst")
    e.add_argument("srcs", nargs="+", help="the members (at least two)")
    e.add_argument("--note", default=None, help="text for the `derived` metadata")
    a = p.parse_args(argv)
    try:
        if a.command == "ensemble":
            note = a.note or (f"ensemble of {len(a.srcs)} files by examples/policy_onnx.py "
                              "ensemble: the mean of their actions, each clipped to the "
                              "action space")
            try:
                low, high = action_bounds(a.srcs[0])
            except ImportError as err:
                raise SystemExit(f"error: ensemble reads the action bounds from the mjskill "
                                 f"package, which is not importable here ({err})") from None
            ensemble(a.srcs, a.dst, note, low, high)
            return
        if a.command == "ease":
            part, _, r = a.near.rpartition(":")
            try:
                radius = float(r)
            except ValueError:
                ea.error(f"--near {a.near!r}: expected NAME:RADIUS, e.g. "
                         "extra/obj_to_goal_pos:0.01")
            most = a.most is not None
            bound = a.most if most else a.least
            try:
                target, near, scale = ease_probe(a.src, a.action, a.target, part)
            except ImportError as err:
                raise SystemExit(f"error: ease reads the observation layout and the action's "
                                 f"scale from the mjskill package, which is not importable "
                                 f"here ({err})") from None
            note = a.note or (f"action {a.action} eased by examples/policy_onnx.py ease: "
                              f"{a.target} {'<=' if most else '>='} {bound:g} while "
                              f"|{part}| < {radius:g}")
            ease_actions(a.src, a.dst, note, a.action, target, scale, bound, near, radius,
                         most, (a.target, part))
            return
        if a.command == "snap":
            try:
                snaps = parse_floors(a.action, "THRESHOLD", "7:-0.75", "threshold", "threshold")
            except ValueError as e:
                sn.error(f"--action {e}")
            note = a.note or ("actions snapped to their bounds by examples/policy_onnx.py snap: "
                              + ", ".join(f"{k} at {v:g}" for k, v in sorted(snaps.items())))
            try:
                low, high = action_bounds(a.src)
            except ImportError as err:
                raise SystemExit(f"error: snap reads the action bounds from the mjskill "
                                 f"package, which is not importable here ({err})") from None
            snap_actions(a.src, a.dst, snaps, note, low, high)
            return
        if a.command == "floor":
            try:
                floors = parse_floors(a.action)
            except ValueError as e:
                f.error(f"--action {e}")
            note = a.note or ("actions floored by examples/policy_onnx.py floor: "
                              + ", ".join(f"{k} >= {v}" for k, v in sorted(floors.items())))
            floor_actions(a.src, a.dst, floors, note)
            return
        if a.command == "retarget":
            note = a.note or f"env_id set to {a.env_id} by examples/policy_onnx.py retarget"
            retarget(a.src, a.dst, a.env_id, note)
            return
        try:
            idx = [int(i) for i in a.obs.split(",")]
        except ValueError:
            h.error(f"--obs {a.obs!r}: expected comma-separated integers, e.g. 16,17")
        note = a.note or f"observation entries {a.obs} hidden by examples/policy_onnx.py hide"
        hide_obs(a.src, a.dst, idx, note)
    except (ValueError, OSError) as e:
        raise SystemExit(f"error: {e}") from None


if __name__ == "__main__":
    main()

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

The graph: input ``obs`` (float32, [batch, obs_dim]); ``x = clip((obs - mean) / std, -clip,
clip)``; then for every layer ``x = x @ W + b``, with ``tanh`` between layers (not after the
last); output ``action`` (float32, [batch, act_dim]), the mean action.
"""

from __future__ import annotations

import json

import numpy as np

#: The metadata_props every policy file carries (docs/training.md).
METADATA_KEYS = ("env_id", "robot_uids", "control_mode", "obs_mode", "training_command")

#: ONNX opset and IR version: old enough for tract and onnxruntime 1.1x alike.
OPSET = 17
IR_VERSION = 8


def mlp_forward(obs, layers, obs_mean, obs_std, obs_clip):
    """The graph's computation in numpy (float64): the reference the tests compare against."""
    x = (np.asarray(obs, np.float64) - obs_mean) / obs_std
    if obs_clip is not None:
        x = np.clip(x, -obs_clip, obs_clip)
    for k, (w, b) in enumerate(layers):
        x = x @ np.asarray(w, np.float64) + np.asarray(b, np.float64)
        if k + 1 < len(layers):
            x = np.tanh(x)
    return x


def write_mlp_policy(path, layers, obs_mean, obs_std, metadata, obs_clip=None):
    """Writes the MLP ``layers`` (a list of (W [in, out], b [out]) arrays) with the observation
    normalisation ``(obs - obs_mean) / obs_std`` (clipped to ±obs_clip unless None) as an ONNX
    policy file at ``path``, with ``metadata`` (a dict of str) as its metadata_props: it must
    hold METADATA_KEYS. Returns the ModelProto."""
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
        out = "action" if last else f"lin{k}"
        nodes.append(helper.make_node("Add", [f"mm{k}", f"b{k}"], [out]))
        if not last:
            nodes.append(helper.make_node("Tanh", [out], [f"h{k}"]))
            x = f"h{k}"
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


def save_derived(model, dst, note, **props):
    """Saves ``model`` as ``dst`` with its metadata updated by ``props`` and ``note`` appended
    to ``derived`` (how the file was edited after training), after onnx's checker."""
    import onnx

    meta = {p.key: p.value for p in model.metadata_props}
    meta.update(props)
    meta["derived"] = "; ".join(x for x in (meta.get("derived", ""), note) if x)
    del model.metadata_props[:]
    onnx.helper.set_model_props(model, meta)
    onnx.checker.check_model(model)
    onnx.save(model, str(dst))
    return model


def hide_obs(src, dst, indices, note):
    """Writes ``src`` as ``dst`` with the observation entries ``indices`` hidden: their rows of
    the first layer become zero and their contribution at observation 0 (after normalisation
    and clipping) moves into the first bias, so the new graph gives, for any observation, the
    action the old one gives with those entries set to 0. Records ``hidden_obs`` and the
    ``note`` (appended to ``derived``) in the metadata. Returns the ModelProto."""
    import onnx
    from onnx import numpy_helper

    model = onnx.load(str(src))
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
    import onnx

    return save_derived(onnx.load(str(src)), dst, note, env_id=env_id)


def floor_actions(src, dst, floors, note):
    """Writes ``src`` as ``dst`` with a lower bound on some action components: ``floors``
    maps an action index to its least value (the others are left as they are), applied to
    the graph's output with ``Max``. Records the ``note`` (appended to ``derived``). Returns
    the ModelProto."""
    import onnx
    from onnx import helper, numpy_helper

    model = onnx.load(str(src))
    g = model.graph
    out = g.output[0]
    act_dim = out.type.tensor_type.shape.dim[-1].dim_value
    if any(not 0 <= k < act_dim for k in floors):
        raise ValueError(f"action indices {sorted(floors)} out of range 0..{act_dim - 1}")
    lo = np.full(act_dim, np.finfo(np.float32).min, np.float32)
    for k, v in floors.items():
        lo[k] = v
    old = out.name
    raw = old + "_unfloored"
    for node in g.node:
        node.output[:] = [raw if o == old else o for o in node.output]
    g.initializer.append(numpy_helper.from_array(lo, "action_floor"))
    g.node.append(helper.make_node("Max", [raw, "action_floor"], [old]))
    return save_derived(model, dst, note)


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
    a = p.parse_args(argv)
    if a.command == "floor":
        floors = {int(x.split(":")[0]): float(x.split(":")[1]) for x in a.action}
        note = a.note or ("actions floored by examples/policy_onnx.py floor: "
                          + ", ".join(f"{k} >= {v}" for k, v in sorted(floors.items())))
        floor_actions(a.src, a.dst, floors, note)
        return
    if a.command == "retarget":
        note = a.note or f"env_id set to {a.env_id} by examples/policy_onnx.py retarget"
        retarget(a.src, a.dst, a.env_id, note)
        return
    idx = [int(i) for i in a.obs.split(",")]
    note = a.note or f"observation entries {a.obs} hidden by examples/policy_onnx.py hide"
    hide_obs(a.src, a.dst, idx, note)


if __name__ == "__main__":
    main()

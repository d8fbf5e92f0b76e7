"""Makes small hostile or faulty policy files (ONNX, docs/training.md) for the tests of the
policy-file rules (tests/hostile_inputs.rs, python/tests/test_policy_rules.py): graphs that
crash or exhaust a runtime, or that two runtimes would run differently. Needs numpy and `onnx`.

    python tests/make_hostile_policy.py KIND --obs-dim 42 --act-dim 4 --out x.onnx [options]

KIND:
  plain          a valid policy: action = tanh(obs @ W)
  gather-oob     a Gather whose index is 1000 where `sign * obs[index] > sign * threshold`
                 (out of range), else 0
  div-zero       an integer division by int(obs[index]) (zero for a zero observation)
  const-shape    a ConstantOfShape of the constant shape --shape (e.g. 1000000000,1000000000)
  loop           a Loop with the constant trip count --trip
  nan-mul-zero   obs[:act] multiplied by a constant zero
  nan-out        NaN actions: sqrt(-1 - |obs[:act]|)
  floor          a plain policy with an action floor (Max with a constant, as
                 examples/policy_onnx.py floor writes) of --value (e.g. nan, inf) at --index
  int64-out, bool-out, rank3-out
                 outputs of the wrong type or rank
  dup-meta       a valid graph with the metadata key --key twice (values --meta-value and
                 "other")
  long-meta      a valid graph whose metadata --key is --length characters long
  bad-utf8-meta  a valid graph whose env_id is not UTF-8
"""

import argparse

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

I64 = TensorProto.INT64
F32 = TensorProto.FLOAT


def const(name, array):
    return numpy_helper.from_array(np.asarray(array), name)


def plain_action(nodes, inits, obs_dim, act_dim, out="action"):
    """action = tanh(obs @ W), W small and seeded."""
    w = np.random.default_rng(0).normal(0, 0.1, (obs_dim, act_dim)).astype(np.float32)
    inits.append(const("W", w))
    nodes.append(helper.make_node("MatMul", ["obs", "W"], ["pre"]))
    nodes.append(helper.make_node("Tanh", ["pre"], [out]))


def column(nodes, inits, index):
    """x = obs[:, index], shape [1, 1]."""
    inits.append(const("col", np.array([index], np.int64)))
    nodes.append(helper.make_node("Gather", ["obs", "col"], ["x"], axis=1))


def build(a):
    nodes, inits = [], []
    out_type, out_shape = F32, [1, a.act_dim]
    k = a.kind
    if k in ("plain", "dup-meta", "long-meta", "bad-utf8-meta"):
        plain_action(nodes, inits, a.obs_dim, a.act_dim)
    elif k == "gather-oob":
        column(nodes, inits, a.index)
        inits += [const("t", np.array([[a.sign * a.threshold]], np.float32)),
                  const("s", np.array([[a.sign]], np.float32)),
                  const("big", np.array([1000], np.int64)),
                  const("flat", np.array([1], np.int64)),
                  const("table", np.zeros((2, a.act_dim), np.float32))]
        nodes += [helper.make_node("Mul", ["x", "s"], ["sx"]),
                  helper.make_node("Greater", ["sx", "t"], ["over"]),
                  helper.make_node("Cast", ["over"], ["over_i"], to=I64),
                  helper.make_node("Reshape", ["over_i", "flat"], ["over_1"]),
                  helper.make_node("Mul", ["over_1", "big"], ["idx"]),
                  helper.make_node("Gather", ["table", "idx"], ["action"], axis=0)]
    elif k == "div-zero":
        column(nodes, inits, a.index)
        inits += [const("seven", np.array([[7]], np.int64)),
                  const("table", np.zeros((1, a.act_dim), np.float32))]
        nodes += [helper.make_node("Cast", ["x"], ["xi"], to=I64),
                  helper.make_node("Div", ["seven", "xi"], ["q"]),
                  helper.make_node("Cast", ["q"], ["qf"], to=F32),
                  helper.make_node("Add", ["table", "qf"], ["action"])]
    elif k == "const-shape":
        shape = [int(float(v)) for v in a.shape.split(",")]
        inits += [const("shape", np.array(shape, np.int64)),
                  const("table", np.zeros((1, a.act_dim), np.float32))]
        nodes += [helper.make_node("ConstantOfShape", ["shape"], ["big"],
                                   value=numpy_helper.from_array(np.array([1.0], np.float32))),
                  helper.make_node("ReduceSum", ["big"], ["total"], keepdims=0),
                  helper.make_node("Add", ["table", "total"], ["action"])]
    elif k == "loop":
        plain_action(nodes, inits, a.obs_dim, a.act_dim, out="a0")
        inits += [const("trip", np.array(a.trip, np.int64)), const("cond", np.array(True))]
        body = helper.make_graph(
            [helper.make_node("Identity", ["cond_in"], ["cond_out"]),
             helper.make_node("Identity", ["v_in"], ["v_out"])],
            "body",
            [helper.make_tensor_value_info("i", I64, []),
             helper.make_tensor_value_info("cond_in", TensorProto.BOOL, []),
             helper.make_tensor_value_info("v_in", F32, [1, a.act_dim])],
            [helper.make_tensor_value_info("cond_out", TensorProto.BOOL, []),
             helper.make_tensor_value_info("v_out", F32, [1, a.act_dim])])
        nodes.append(helper.make_node("Loop", ["trip", "cond", "a0"], ["action"], body=body))
    elif k == "nan-mul-zero":
        inits += [const("cols", np.arange(a.act_dim, dtype=np.int64)),
                  const("zero", np.zeros((1, a.act_dim), np.float32))]
        nodes += [helper.make_node("Gather", ["obs", "cols"], ["xs"], axis=1),
                  helper.make_node("Mul", ["xs", "zero"], ["action"])]
    elif k == "nan-out":
        inits += [const("cols", np.arange(a.act_dim, dtype=np.int64)),
                  const("minus1", np.array([[-1.0]], np.float32))]
        nodes += [helper.make_node("Gather", ["obs", "cols"], ["xs"], axis=1),
                  helper.make_node("Abs", ["xs"], ["ax"]),
                  helper.make_node("Sub", ["minus1", "ax"], ["neg"]),
                  helper.make_node("Sqrt", ["neg"], ["action"])]
    elif k == "floor":
        plain_action(nodes, inits, a.obs_dim, a.act_dim, out="raw")
        lo = np.full(a.act_dim, np.finfo(np.float32).min, np.float32)
        lo[a.index] = np.float32(float(a.value))
        inits.append(const("action_floor", lo))
        nodes.append(helper.make_node("Max", ["raw", "action_floor"], ["action"]))
    elif k in ("int64-out", "bool-out", "rank3-out"):
        plain_action(nodes, inits, a.obs_dim, a.act_dim, out="a0")
        if k == "int64-out":
            out_type = I64
            nodes.append(helper.make_node("Cast", ["a0"], ["action"], to=I64))
        elif k == "bool-out":
            out_type = TensorProto.BOOL
            nodes.append(helper.make_node("Cast", ["a0"], ["action"], to=TensorProto.BOOL))
        else:
            out_shape = [1, 1, a.act_dim]
            inits.append(const("three", np.array([1, 1, a.act_dim], np.int64)))
            nodes.append(helper.make_node("Reshape", ["a0", "three"], ["action"]))
    else:
        raise SystemExit(f"unknown kind {k}")
    graph = helper.make_graph(
        nodes, "policy", [helper.make_tensor_value_info("obs", F32, [1, a.obs_dim])],
        [helper.make_tensor_value_info("action", out_type, out_shape)], inits)
    opset = [helper.make_opsetid("", 17)]
    return helper.make_model(graph, opset_imports=opset, ir_version=8)


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("kind")
    p.add_argument("--obs-dim", type=int, required=True)
    p.add_argument("--act-dim", type=int, required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--env-id", default="PickCube-v1")
    p.add_argument("--robot", default="panda")
    p.add_argument("--control-mode", default="pd_ee_delta_pos")
    p.add_argument("--index", type=int, default=0)
    p.add_argument("--threshold", type=float, default=0.0)
    p.add_argument("--sign", type=float, default=1.0)
    p.add_argument("--value", default="0.5", help="the floor of `floor` (nan and inf too)")
    p.add_argument("--shape", default="1000000000,1000000000")
    p.add_argument("--trip", type=int, default=10**15)
    p.add_argument("--key", default="control_mode")
    p.add_argument("--meta-value", default="pd_joint_delta_pos")
    p.add_argument("--length", type=int, default=20_000_000)
    a = p.parse_args()
    model = build(a)
    meta = {"env_id": a.env_id, "robot_uids": a.robot, "control_mode": a.control_mode,
            "obs_mode": "state", "training_command": f"tests/make_hostile_policy.py {a.kind}"}
    if a.kind == "long-meta":
        meta[a.key] = "x" * a.length
    if a.kind == "bad-utf8-meta":
        meta["env_id"] = "BADUTF8MARKER"
    for key, value in meta.items():
        model.metadata_props.add(key=key, value=value)
    if a.kind == "dup-meta":
        model.metadata_props.add(key=a.key, value=a.meta_value)
    data = model.SerializeToString()
    if a.kind == "bad-utf8-meta":
        data = data.replace(b"BADUTF8MARKER", b"\xff\xfe\xfd\xfc\xfb\xfa\xf9\xf8\xf7\xf6\xf5\xf4\xf3")
    with open(a.out, "wb") as f:
        f.write(data)


if __name__ == "__main__":
    main()

"""Makes a small mjskill policy file with deterministic random weights: an MLP with observation
normalisation and the metadata (docs/training.md). The tests (tests/policy_file.rs,
python/tests/test_policy.py) make theirs with it; it needs numpy and `onnx` only.

    python examples/make_test_policy.py --obs-dim 42 --act-dim 4 --out test.onnx \
        --env-id PickCube-v1 --robot panda --control-mode pd_ee_delta_pos

--weights-json also writes the weights (float32 values) as JSON; --check compares the graph's
output (onnx's reference evaluator) against numpy's on random observations. --meta KEY=VALUE
sets or overrides a metadata entry, --drop-meta KEY leaves one out (to make defective files
for tests).
"""

import argparse
import os
import shlex
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from policy_onnx import METADATA_KEYS, mlp_forward, save_weights_json, write_mlp_policy  # noqa: E402


def make_layers(rng, obs_dim, hidden, act_dim, scale):
    """Seeded layers (W [in, out], b [out]); `scale` multiplies the last layer (large values
    exercise the action clipping)."""
    sizes = [obs_dim, *hidden, act_dim]
    layers = []
    for k, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        w = rng.normal(0.0, 1.0 / np.sqrt(n_in), size=(n_in, n_out))
        b = rng.normal(0.0, 0.1, size=n_out)
        if k + 2 == len(sizes):
            w, b = w * scale, b * scale
        layers.append((w.astype(np.float32), b.astype(np.float32)))
    return layers


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--obs-dim", type=int, required=True)
    p.add_argument("--act-dim", type=int, required=True)
    p.add_argument("--hidden", type=int, nargs="*", default=[32, 32])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--scale", type=float, default=2.0, help="last-layer scale")
    p.add_argument("--obs-clip", type=float, default=5.0)
    p.add_argument("--out", required=True)
    p.add_argument("--env-id", default="PickCube-v1")
    p.add_argument("--robot", default="panda")
    p.add_argument("--control-mode", default="pd_ee_delta_pos")
    p.add_argument("--obs-mode", default="state")
    p.add_argument("--meta", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--drop-meta", action="append", default=[], metavar="KEY")
    p.add_argument("--weights-json")
    p.add_argument("--check", action="store_true")
    a = p.parse_args()

    rng = np.random.default_rng(a.seed)
    layers = make_layers(rng, a.obs_dim, a.hidden, a.act_dim, a.scale)
    obs_mean = rng.normal(0.0, 0.3, size=a.obs_dim).astype(np.float32)
    obs_std = rng.uniform(0.2, 2.0, size=a.obs_dim).astype(np.float32)
    metadata = {
        "env_id": a.env_id,
        "robot_uids": a.robot,
        "control_mode": a.control_mode,
        "obs_mode": a.obs_mode,
        "training_command": "python " + " ".join(shlex.quote(x) for x in sys.argv),
    }
    for kv in a.meta:
        k, _, v = kv.partition("=")
        metadata[k] = v
    if a.drop_meta:
        # Written through the builder with every key, then the dropped ones removed.
        import onnx

        model = write_mlp_policy(a.out, layers, obs_mean, obs_std, metadata, a.obs_clip)
        kept = [p for p in model.metadata_props if p.key not in a.drop_meta]
        del model.metadata_props[:]
        model.metadata_props.extend(kept)
        onnx.save(model, a.out)
    else:
        write_mlp_policy(a.out, layers, obs_mean, obs_std, metadata, a.obs_clip)
    if a.weights_json:
        save_weights_json(a.weights_json, layers, obs_mean, obs_std, a.obs_clip)
    if a.check:
        from onnx.reference import ReferenceEvaluator

        obs = rng.normal(0.0, 1.0, size=(16, a.obs_dim)).astype(np.float32)
        got = ReferenceEvaluator(a.out).run(None, {"obs": obs})[0]
        want = mlp_forward(obs, layers, obs_mean, obs_std, a.obs_clip)
        err = float(np.max(np.abs(got - want)))
        print(f"max |onnx - numpy| = {err:.3g}")
        if err > 1e-4:
            sys.exit(f"the graph disagrees with numpy by {err}")
    assert set(METADATA_KEYS) <= set(metadata)


if __name__ == "__main__":
    main()

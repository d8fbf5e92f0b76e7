"""A real two-node Ray cluster on this machine: a head node and a worker node (two
`ray start`s, one CPU each), token authentication on, every node at 127.0.0.1. RayVectorEnv
puts one actor on each node and must give the local vector env's buffers bit for bit; with
torch, examples/ppo.py --ray-workers 2 on the cluster must learn the local run's weights.

The cluster runs inside a network namespace that has only the loopback interface
(`unshare -n`, as root or in a user namespace), made for it by the test: ray_two_nodes.py
says why, and docs/training.md how to run on a real cluster."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO, need
from mjskill import MjskillVectorEnv
from rollout_case import (ENV_ID, KW, NUM_ENVS, RESET_SEED, STEPS, ppo_args, rollout,
                          rollout_params)

DRIVER = Path(__file__).with_name("ray_two_nodes.py")


def loopback_only(cmd: list[str]) -> list[str]:
    """``cmd`` in a new network namespace with the loopback interface up and nothing else
    (root: ``unshare -n``; anyone else also a user namespace, ``unshare -r -n``)."""
    ns = ["unshare", "-n"] if os.geteuid() == 0 else ["unshare", "-r", "-n"]
    return [*ns, "sh", "-c", 'ip link set lo up && exec "$@"', "sh", *cmd]


def two_nodes(tmp_path: Path, *extra: str) -> dict:
    need("ray")
    probe = subprocess.run(loopback_only(["true"]), capture_output=True, text=True)
    if probe.returncode != 0:
        why = f"no network namespace for the cluster: {probe.stderr.strip()}"
        if os.environ.get("CI") or os.environ.get("MJSKILL_WHEEL_TEST"):
            pytest.fail(why)
        pytest.skip(why)
    out = tmp_path / "remote.npz"
    r = subprocess.run(loopback_only([sys.executable, str(DRIVER), str(out), *extra]),
                       capture_output=True, text=True, timeout=900)
    logs = "".join(f"\n--- {p.name}:\n{p.read_text()[-3000:]}"
                   for p in (tmp_path / "head.log", tmp_path / "worker.log") if p.exists())
    assert r.returncode == 0, f"{r.stdout[-2000:]}\n{r.stderr[-3000:]}{logs}"
    report = json.loads(r.stdout.strip().splitlines()[-1])
    report["buffers"] = dict(np.load(out))
    return report


def test_rollouts_on_two_nodes_equal_the_local_vector_env_bit_for_bit(tmp_path):
    report = two_nodes(tmp_path)
    # Two nodes, both on loopback (the driver refuses to run otherwise), one actor on each.
    assert len(report["nodes"]) == 2 and {ip for _, ip in report["nodes"]} == {"127.0.0.1"}
    assert report["tokenless_node"] == "refused"
    actor_nodes = [node for node, _ in report["actors"]]
    assert sorted(actor_nodes) == sorted(node for node, _ in report["nodes"]), report
    remote = report["buffers"]
    local = MjskillVectorEnv(ENV_ID, num_envs=NUM_ENVS, num_threads=2, **KW)
    np.testing.assert_array_equal(remote["reset"], local.reset(seed=RESET_SEED)[0])
    for it, p in enumerate(rollout_params(local)):
        buffers, last = rollout(local, p, STEPS, first_step=it * STEPS)
        for key, value in buffers.items():
            np.testing.assert_array_equal(remote[f"{it}/{key}"], value, err_msg=f"{it}/{key}")
        np.testing.assert_array_equal(remote[f"{it}/last"], last)
    # Something happened: the envs moved, and some episode ended within each call.
    assert not np.array_equal(remote["0/last"], remote["reset"])
    assert remote["0/truncated"].any() and remote["1/truncated"].any()


def test_ppo_with_two_ray_workers_on_two_nodes_learns_the_local_weights(tmp_path):
    torch = pytest.importorskip("torch")
    report = two_nodes(tmp_path, "--ppo", str(tmp_path / "ray"))
    assert report["ran"] == ["rollout", "ppo"]
    local_out = tmp_path / "local"
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    subprocess.run([sys.executable, str(REPO / "examples" / "ppo.py"), *ppo_args(local_out)],
                   check=True, env=env, capture_output=True, timeout=600)
    local = torch.load(local_out / "policy.pt", weights_only=False)
    remote = torch.load(tmp_path / "ray" / "policy.pt", weights_only=False)
    for part in ("actor", "critic"):
        for key, value in local[part].items():
            assert torch.equal(value, remote[part][key]), f"{part}.{key}"
    assert torch.equal(local["logstd"], remote["logstd"])
    np.testing.assert_array_equal(local["obs_mean"], remote["obs_mean"])

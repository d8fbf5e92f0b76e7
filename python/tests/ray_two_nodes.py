"""A real two-node Ray cluster on this machine, for python/tests/test_ray_cluster.py.

Run inside a network namespace of its own that has only the loopback interface
(``unshare -n``; the test makes it): Ray names every node by the address it would be reached
at, and in such a namespace that can only be 127.0.0.1. On the machine's own network
namespace Ray 2.x resolves 127.0.0.1 to the machine's routable address even when told
``--node-ip-address=127.0.0.1`` (it refuses loopback node addresses for clusters), so the
namespace is what keeps every node, and everything they open, on loopback.

Starts a head node and a worker node with ``ray start --block``, one CPU each, both with
token authentication on and one fresh token (``RAY_AUTH_MODE=token``, ``RAY_AUTH_TOKEN``): a
node started without the head's token is refused, and nothing is read from or written to
``~/.ray``. Checks that both nodes are up and at 127.0.0.1 (refusing to go on otherwise) and that a
third node without the token is refused, then runs :class:`mjskill.ray.RayVectorEnv` with one actor on each node and saves its
buffers; with ``--ppo DIR``, also trains examples/ppo.py with ``--ray-workers 2`` on the
cluster. Prints one JSON line: the nodes, where each actor ran, what ran. Stops both nodes
on the way out.

Usage: python ray_two_nodes.py OUT.npz [--ppo DIR]
"""

import argparse
import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(HERE))
from rollout_case import ENV_ID, KW, NUM_ENVS, RESET_SEED, STEPS, ppo_args, rollout_params  # noqa: E402

# The `ray` command of this interpreter's Ray (its console script's module).
RAY = [sys.executable, "-m", "ray.scripts.scripts"]
PORT = 6379
START_TIMEOUT_S = 120


def node_env(token: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token, RAY_USAGE_STATS_ENABLED="0")
    return env


def start(args: list, env: dict, log: Path) -> subprocess.Popen:
    # Its own process group: stopping it stops every process `ray start` started.
    return subprocess.Popen([*RAY, "start", "--block", "--num-cpus=1", "--num-gpus=0",
                             "--disable-usage-stats", *args], env=env,
                            stdout=log.open("w"), stderr=subprocess.STDOUT,
                            start_new_session=True)


def stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        os.killpg(p.pid, signal.SIGTERM)
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def report(obj: dict) -> None:
    # Flushed at once: once the nodes stop, Ray's core worker in this process may end it.
    print(json.dumps(obj), flush=True)


def alive_nodes(ray) -> list:
    return [n for n in ray.nodes() if n["Alive"]]


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--ppo")
    a = p.parse_args()
    out = Path(a.out)
    token = secrets.token_hex(32)
    env = node_env(token)
    address = f"127.0.0.1:{PORT}"
    nodes = []
    # Ray's sockets live in its temporary directory, whose paths must stay short (107 bytes).
    temp = tempfile.mkdtemp(prefix="mjskill-ray-")
    try:
        nodes.append(start(["--head", f"--port={PORT}", "--node-ip-address=127.0.0.1",
                            "--include-dashboard=false", f"--temp-dir={temp}"],
                           env, out.parent / "head.log"))
        # The worker node's dashboard agent needs a port of its own: the head's takes the
        # default (52365) on the same loopback.
        nodes.append(start([f"--address={address}", "--dashboard-agent-listen-port=52366"],
                           env, out.parent / "worker.log"))
        os.environ.update(env)
        import ray

        ray.init(address=address, log_to_driver=False)
        deadline = time.monotonic() + START_TIMEOUT_S
        while len(alive_nodes(ray)) < 2:
            if time.monotonic() > deadline or any(n.poll() is not None for n in nodes):
                report({"error": "the two nodes did not come up",
                                  "nodes": [n["NodeManagerAddress"] for n in alive_nodes(ray)]})
                return 2
            time.sleep(0.5)
        seen = [(n["NodeID"], n["NodeManagerAddress"]) for n in alive_nodes(ray)]
        if any(ip != "127.0.0.1" for _, ip in seen):
            report({"error": "a node is not at 127.0.0.1: refusing to run",
                              "nodes": seen})
            return 3

        # Token authentication is on: a node without the token is refused (HOME elsewhere,
        # so that no ~/.ray/auth_token stands in for it).
        stranger = {**{k: v for k, v in env.items() if not k.startswith("RAY_AUTH")},
                    "HOME": temp}
        r = subprocess.run([*RAY, "start", f"--address={address}", "--num-cpus=1",
                            "--dashboard-agent-listen-port=52367"], env=stranger,
                           capture_output=True, text=True, timeout=120)
        refused = r.returncode != 0 and "token" in (r.stdout + r.stderr).lower()
        if not refused or len(alive_nodes(ray)) != 2:
            report({"error": "a node without the token was not refused",
                    "returncode": r.returncode, "output": (r.stdout + r.stderr)[-2000:]})
            return 4

        from mjskill.ray import RayVectorEnv

        remote = RayVectorEnv(ENV_ID, NUM_ENVS, workers=2, **KW)
        where = remote.nodes()
        saved = {"reset": remote.reset(seed=RESET_SEED)}
        for it, params in enumerate(rollout_params(remote)):
            buffers = remote.rollout_buffers(STEPS)
            saved[f"{it}/last"] = remote.rollout(params, it * STEPS, buffers)
            saved.update({f"{it}/{k}": v for k, v in buffers.items()})
        remote.close()
        np.savez(out, **saved)
        ran = ["rollout"]
        if a.ppo:
            ray.shutdown()
            subprocess.run([sys.executable, str(REPO / "examples" / "ppo.py"),
                            *ppo_args(Path(a.ppo)), "--ray-workers", "2"],
                           env={**env, "RAY_ADDRESS": address}, check=True,
                           capture_output=True, timeout=600)
            ran.append("ppo")
        report({"nodes": seen, "actors": where, "ran": ran, "tokenless_node": "refused"})
        return 0
    finally:
        if "ray" in sys.modules:
            sys.modules["ray"].shutdown()
        for n in reversed(nodes):
            stop(n)
        shutil.rmtree(temp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())

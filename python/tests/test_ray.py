"""Ray sharding: seed-range shards on local Ray workers, each a native vector env writing an
.mcap shard; merged statistics equal one process doing all seeds, and `mjskill info DIR`
reads the shards as one dataset."""

import json
import subprocess

import numpy as np
import pytest
import ray

import mjskill.ray as mray
from conftest import mjskill_bin


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def test_sharded_rollout_equals_one_process(local_ray, tmp_path):
    seeds = range(20, 33)  # 13 episodes: uneven shards and a partial vector batch
    sharded = mray.rollout(
        "PickCube-v1", seeds, tmp_path / "ray", num_workers=2, num_envs=4, policy="random"
    )
    single = mray.rollout(
        "PickCube-v1", seeds, tmp_path / "one", num_workers=1, num_envs=4, use_ray=False
    )
    assert len(sharded["shards"]) == 2 and len(single["shards"]) == 1
    assert sharded["seeds"] == single["seeds"] == list(seeds)
    assert sharded["returns"] == single["returns"], "bitwise equal per episode"
    assert sharded["episode_successes"] == single["episode_successes"]
    for key in ("episodes", "successes", "success_rate", "mean_return", "steps"):
        assert sharded[key] == single[key], key
    assert sharded["steps"] == 13 * 50, "random actions never succeed: every episode truncates"
    assert len(set(sharded["returns"])) == 13, "each seed is its own episode"

    info = json.loads(subprocess.check_output([mjskill_bin(), "info", str(tmp_path / "ray")]))
    assert info["episodes"] == 13 and info["complete"] is True
    assert len(info["shards"]) == 2
    assert info["successes"] == sharded["successes"]
    assert info["steps"] == sharded["steps"]
    assert np.isclose(info["mean_return"], sharded["mean_return"], rtol=1e-12)
    shard = info["shards"][1]["file"]
    replay = json.loads(subprocess.check_output([mjskill_bin(), "replay", shard]))
    assert replay["ok"] is True, "the shard re-simulates exactly"
    assert replay["episodes"] == info["shards"][1]["episodes"] == 7
    one = json.loads(subprocess.check_output([mjskill_bin(), "info", str(tmp_path / "one")]))
    assert one["episodes"] == 13 and np.isclose(one["mean_return"], info["mean_return"], rtol=1e-12)


def test_callable_policy_and_a_different_shard_count_agree(local_ray, tmp_path):
    def policy(obs):  # a deterministic function of each observation row
        return np.clip(np.tanh(obs[:, :8] * 3.0), -1, 1).astype(np.float32)

    a = mray.rollout("PickCube-v1", range(0, 6), tmp_path / "a", num_workers=3, num_envs=2,
                     policy=policy)
    b = mray.rollout("PickCube-v1", range(0, 6), tmp_path / "b", num_workers=2, num_envs=3,
                     policy=policy)
    assert a["returns"] == b["returns"] and len(a["shards"]) == 3


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="unknown policy 'smart'; valid policies: random, zero"):
        mray.rollout("PickCube-v1", range(2), tmp_path, policy="smart", use_ray=False)
    with pytest.raises(ValueError, match="leave the 32-bit range"):
        mray.rollout("PickCube-v1", [2**32], tmp_path, use_ray=False)
    with pytest.raises(ValueError, match="valid env ids"):
        mray.rollout("Nope-v1", range(2), tmp_path, use_ray=False)
    assert not list(tmp_path.glob("*.mcap")), "nothing written on failure"


def test_a_shard_of_peg_insertion_side_records_each_seeds_own_shapes(tmp_path):
    # A batch keeps its construction shapes unless a reset asks for a redraw; a shard's
    # episodes are their seeds' (the recorder re-simulates them in one env and must agree).
    out = mray.run_shard("PegInsertionSide-v1", [7, 8, 9], tmp_path / "peg.mcap", num_envs=2,
                         policy="zero")
    assert out["seeds"] == [7, 8, 9] and out["steps"] == [100, 100, 100]

"""examples/eval_in_maniskill.py without ManiSkill: the order of the episodes' seeds for each
`--history`."""

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "examples"))
import eval_in_maniskill as ev  # noqa: E402


def test_sequential_and_fresh_histories_run_the_seeds_in_order():
    for history in ("sequential", "fresh"):
        assert ev.episode_seeds(10000, 4, history) == [10000, 10001, 10002, 10003]


def test_the_reversed_history_runs_the_same_seeds_last_first():
    assert ev.episode_seeds(10000, 4, "reversed") == [10003, 10002, 10001, 10000]
    assert ev.episode_seeds(7, 1, "reversed") == [7]


def test_every_history_has_its_order():
    for history in ev.HISTORIES:
        assert sorted(ev.episode_seeds(5, 3, history)) == [5, 6, 7]

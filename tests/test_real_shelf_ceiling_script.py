"""experiments/real/shelf_ceiling.py: people grouped by the ground truth, on a view whose
answer is known and on the made-up stand-in for Shelf (perfect detections: the ceiling is
every part and joint)."""

import os
import runpy

import numpy as np
from test_real_shelf_script import _write_standin

HERE = os.path.dirname(os.path.abspath(__file__))
ceiling = runpy.run_path(
    os.path.join(HERE, "..", "experiments", "real", "shelf_ceiling.py"), run_name="shelf_ceiling"
)
BODY25 = ceiling["ANNOTATED"]


def _person(uv: np.ndarray, offset=(0.0, 0.0)) -> np.ndarray:
    """A BODY_25 person ``(25, 3)`` holding the annotated joints at ``uv (15, 2)`` + offset."""
    person = np.zeros((25, 3))
    for s, b in BODY25.items():
        person[b] = (*(uv[s] + offset), 0.9)
    return person


def test_people_go_to_the_nearest_actor_within_the_radius():
    uv = {
        0: np.c_[np.arange(15.0) * 20, np.zeros(15)],
        1: np.c_[np.arange(15.0) * 20, 300 + np.zeros(15)],
    }
    near_1 = _person(uv[1], (3.0, 0.0))
    near_0 = _person(uv[0], (5.0, 0.0))
    far = _person(uv[0], (0.0, 100.0))
    assert ceiling["assign_people"]([far, near_1, near_0], uv, radius=40.0) == {1: 1, 0: 2}
    assert ceiling["assign_people"]([far], uv, radius=40.0) == {}  # 100 px from actor 0
    few = np.zeros((25, 3))
    few[[BODY25[0], BODY25[1]]] = (*uv[0][0], 0.9), (*uv[0][1], 0.9)  # two joints: too few
    assert ceiling["assign_people"]([few], uv, radius=40.0) == {}


def test_the_stand_in_reaches_every_part(tmp_path):
    _write_standin(str(tmp_path))
    rows = ceiling["main"]([str(tmp_path), "--split", "all", "--json", str(tmp_path / "c.json")])
    assert [r["setting"].split(", ")[-1] for r in rows] == ["by person", "by joint"]
    for row in rows:
        assert row["pcp_mean"] == 100.0 and row["recall_10cm"] == 1.0
        assert row["mpjpe_mm"] < 1.0 and row["scored"] == 6  # 2 actors × 3 frames


def test_a_detection_serves_one_joint_nearest_pairs_first():
    at = [np.array([0.0, 0.0]), np.array([10.0, 0.0]), np.array([np.nan, np.nan])]
    dets = np.array([[8.0, 0.0], [100.0, 0.0]])  # the first nearer joint 1 (2 px) than 0 (8)
    assert ceiling["nearest_pairs"](at, dets, radius=40.0) == [(1, 0)]
    assert ceiling["nearest_pairs"](at, dets, radius=1.0) == []
    assert ceiling["nearest_pairs"](at, np.zeros((0, 2)), radius=40.0) == []

"""experiments/real/shelf_detections.py: its counts on a scene whose answer is known, and the
script on the made-up stand-in for Shelf (perfect detections: every joint found); and
shelf_generator_check.py on the stand-in's cameras."""

import os
import runpy

import numpy as np
import pytest
from test_real_shelf_script import _write_standin

HERE = os.path.dirname(os.path.abspath(__file__))
stats = runpy.run_path(
    os.path.join(HERE, "..", "experiments", "real", "shelf_detections.py"),
    run_name="shelf_detections",
)
BODY25 = runpy.run_path(os.path.join(HERE, "..", "experiments", "real", "shelf_score.py"))[
    "BODY25_OF_SHELF"
]


def test_found_swapped_missed_hidden_doubles_and_unexplained():
    # One camera 5 m from the plane z = 0: a point (x, y, 0) lands at (500 + 20x, 400 + 20y).
    K = np.array([[[100.0, 0, 500], [0, 100, 400], [0, 0, 1]]])
    R, t = np.eye(3)[None], np.array([[0.0, 0, 5]])
    far = np.zeros((15, 3))
    far[:12, 0] = np.arange(12)  # actor 0's limb joint j at pixel (500 + 20 j, 400)
    near = np.zeros((15, 3))  # actor 1, 1 m nearer, its image box over actor 0's joint 3
    near[:12] = np.c_[np.linspace(2.0, 2.8, 12), np.linspace(-0.2, 0.2, 12), -np.ones(12)]
    person = np.zeros((25, 3))
    for j in range(12):
        person[BODY25[j]] = (500 + 20 * j, 400, 0.9)
    person[BODY25[0], :2] += (1, 2)  # found, 1 px right and 2 down
    person[BODY25[3], 2] = 0.0  # missed, and hidden by actor 1
    person[BODY25[6], 2] = 0.0  # no right wrist, but a left wrist where it is: swapped
    person[BODY25[11], :2] = (500 + 20 * 6, 400)  # (so the left wrist is missed)
    other = np.zeros((25, 3))
    other[BODY25[1]] = (500 + 20 * 1 + 2, 400, 0.8)  # a second right knee: a double
    other[BODY25[0]] = (100, 100, 0.8)  # a right ankle near no actor: unexplained
    views = [[[person, other]]]
    out = stats["detection_stats"](
        views, [{0: far, 1: near}], K, R, t, (1000, 800), [0], radius=5.0
    )
    assert out["joint_views"] == 24  # actor 1 has no detection: its 12 joints are missed
    assert np.isclose(out["found"], 9 / 24) and np.isclose(out["swapped"], 1 / 24)
    assert np.isclose(out["missed"], 14 / 24)
    assert np.isclose(out["hidden_share"], 1 / 24) and out["missed_when_hidden"] == 1.0
    assert np.isclose(out["doubles"], 1 / 24) and out["unexplained_per_view_frame"] == 1.0
    joints = out["per_joint"]
    assert joints["right ankle"]["median_error_px"] == np.hypot(1, 2)  # actor 1 missed it
    assert joints["right wrist"]["swapped"] == 0.5 and joints["left wrist"]["missed"] == 1.0


def test_the_script_on_the_standin(tmp_path):
    folder = str(tmp_path / "shelf")
    os.makedirs(folder)
    _write_standin(folder)
    out = stats["main"]([folder, "--split", "all", "--json", str(tmp_path / "d.json")])
    assert out["frames"] == 3 and out["joint_views"] == 3 * 2 * 12 * 5
    assert out["found"] == 1.0 and out["missed"] == 0.0 and out["swapped"] == 0.0
    assert out["error_p99_px"] < 1e-3 and out["unexplained_per_view_frame"] == 0.0
    assert os.path.exists(tmp_path / "d.json")


def test_cameras_seeing_a_person_need_most_of_its_joints_in_their_image():
    # One camera 5 m from the plane z = 0 (1000 × 800 px): (x, y, 0) lands at
    # (500 + 20 x, 400 + 20 y); a second camera looks the other way.
    K = np.array([[[100.0, 0, 500], [0, 100, 400], [0, 0, 1]]] * 2)
    R = np.array([np.eye(3), np.diag([1.0, -1.0, -1.0])])
    t = np.array([[0.0, 0, 5], [0.0, 0, -5]])
    joints = np.zeros((3, 12, 3))
    joints[0, :, 0] = np.linspace(-5, 5, 12)  # all 12 inside the first image
    joints[1, :, 0] = np.linspace(-5, 35, 12)  # a third of them beyond its right edge
    joints[2, :, 2] = -6.0  # behind the first camera, in the second's image
    seen = stats["cameras_seeing"](K, R, t, (1000, 800), joints)
    assert seen.tolist() == [1, 0, 1]
    # Ten of twelve joints inside (83 %) is seen; nine (75 %) is not.
    joints[1, :, 0] = np.r_[np.zeros(10), 30.0, 30.0]
    assert stats["cameras_seeing"](K, R, t, (1000, 800), joints)[1] == 1
    joints[1, :, 0] = np.r_[np.zeros(9), 30.0, 30.0, 30.0]
    assert stats["cameras_seeing"](K, R, t, (1000, 800), joints)[1] == 0


def _generator_check_on_standin(tmp_path):
    """shelf_generator_check.py's functions, and the made-up stand-in's folder."""
    folder = str(tmp_path / "shelf")
    os.makedirs(folder)
    _write_standin(folder)
    check = runpy.run_path(
        os.path.join(HERE, "..", "experiments", "real", "shelf_generator_check.py"),
        run_name="shelf_generator_check",
    )
    return check, folder


def test_the_generator_check_on_the_standin(tmp_path):
    check, folder = _generator_check_on_standin(tmp_path)
    real = tmp_path / "real.json"
    real.write_text('[{"row": "paper()", "recall_10cm": 0.5}]')
    table = check["main"](
        [
            folder,
            "--real-json",
            str(real),
            "--presets",
            "paper",
            "--sequences",
            "1",
            "--frames",
            "2",
        ]
    )
    row = table["paper"]
    assert row["shelf dev frames"] == 0.5
    # Noise of 5 px at 4 m: the clean scenes' joints are found; the detector's misses cost.
    assert row["clean"] > 0.9 and row["+ keypoint errors"] < row["clean"]
    # Far-off detections on top of the detector's misses: no joint is gained.
    assert row["+ error tails"] <= row["+ keypoint errors"]
    # The people of the clean scenes: every part of the three actors within half its length.
    assert table["pcp"]["shelf dev frames"] is None and table["pcp"]["clean"] > 90.0


def test_the_generator_check_leaves_out_a_stage(tmp_path):
    """``--left-out``: a preset with one stage left out, joint by joint on the stand-in (as on
    Shelf's dev frames) and on the synthetic scenes, beside the preset's own recall."""
    check, folder = _generator_check_on_standin(tmp_path)
    rig, size = check["shelf_rig"](folder)
    scenes = check["synthetic_scenes"](
        rig, size, sigma=5.0, view_spread=0.22, errors=True, sequences=1, frames=2
    )
    # --nu: the same scenes (people, misses) with Student-t noise, its bulk's spread kept.
    heavy = check["synthetic_scenes"](
        rig, size, sigma=5.0, view_spread=0.22, errors=True, sequences=1, frames=2, nu=3.0
    )
    assert np.array_equal(heavy[1], scenes[1]) and np.array_equal(heavy[2], scenes[2])
    moved = np.abs(heavy[0] - scenes[0])[scenes[1]]
    assert np.median(moved) < 1.0 and np.max(moved) > 10.0  # the bulk kept, the tail grown
    # The people every camera sees: the stand-in's cameras ring the walking area.
    seen = check["seen_by_every_camera"](rig, size, scenes[3])
    assert seen.shape == scenes[4].shape and 0 < np.sum(seen & scenes[4]) <= np.sum(scenes[4])
    table = {"extended": {"shelf dev frames": 0.5, "+ keypoint errors": 0.75}}
    (row,) = check["left_out_rows"](
        folder, str(tmp_path / "work"), rig, scenes, ["extended() − regroup"], table
    )
    # On the stand-in's clean frames every joint is found without the stage; what it is
    # worth is the preset's recall less the row's, on each yardstick.
    assert row["row"] == "extended() − regroup" and row["shelf"] == 1.0
    assert row["worth_on_shelf"] == 0.5 - 1.0
    assert 0.0 <= row["synthetic"] <= 1.0 and row["worth_on_synthetic"] == 0.75 - row["synthetic"]
    # Rows it does not have, or whose preset the command does not run, are refused first.
    base = [folder, "--real-json", str(tmp_path / "none.json"), "--presets", "paper"]
    for wrong in (["--left-out", "no such"], ["--left-out", "best() − seed"]):
        with pytest.raises(SystemExit):
            check["main"](base + wrong)


def test_the_robustness_study_makes_each_setting_harder_one_thing_at_a_time(tmp_path):
    """``--robustness``: the fitted generator's scenes, then one thing at a time made harder
    (the same people and motion in every setting: one draw)."""
    check, folder = _generator_check_on_standin(tmp_path)
    rig, size = check["shelf_rig"](folder)
    settings = check["robustness_settings"](6.0, 3.0)
    assert settings["fitted"]["sigma"] == 6.0 and settings["σ × 1.5"]["sigma"] == 9.0
    assert all(s["nu"] == 3.0 and s["view_spread"] == 0.22 for s in settings.values())

    def scenes(name):
        return check["synthetic_scenes"](rig, size, sequences=1, frames=2, **settings[name])

    fitted, misses, clutter, crowd = (
        scenes(n) for n in ("fitted", "misses × 2", "clutter 5 / view", "6–8 people")
    )
    # Twice the detector's misses: fewer of the same people's joints detected.
    assert misses[0].shape == fitted[0].shape and misses[1].sum() < fitted[1].sum()
    # Clutter: slots beyond the people's joints, holding detections of no person.
    assert clutter[1].shape[-1] > fitted[1].shape[-1]
    assert np.sum(clutter[1] & (clutter[5] < 0)) > np.sum(fitted[1] & (fitted[5] < 0))
    # A crowd: room for 8 people, and more of them in the scenes.
    assert crowd[4].shape[1] == 8 and crowd[4].sum() > fitted[4].sum()
    # The study is not a check: the stages it would leave out are read from the check's scenes.
    with pytest.raises(SystemExit):
        check["main"]([folder, "--robustness", "--left-out", "all"])

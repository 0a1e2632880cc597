"""`cdog-jax associate` on a sequence: every output carries the groups' track ids, and
``--temporal-prior`` / ``--track-step-px`` reach the tracking."""

import csv
import json

import numpy as np
import pytest
from helpers import project_np, ring_rig

from cdog_jax.cli import main
from cdog_jax.io import save_rig


def test_associate_writes_track_ids(tmp_path, capsys):
    rig = ring_rig(num_views=3)
    X0 = np.array([[0.2, 0.0, 0.1], [-0.3, 0.2, 0.0]])
    frames = []
    for f in range(3):
        xy, _ = project_np(rig, X0 + np.array([0.05, 0.0, 0.0]) * f)
        order = [1, 0] if f == 1 else [0, 1]  # slots swapped in frame 1
        frames.append({"views": [[[float(v) for v in xy[m, i]] for i in order] for m in range(3)]})
    points, rig_path = tmp_path / "frames.json", tmp_path / "rig.json"
    points.write_text(json.dumps({"frames": frames}))
    save_rig(rig_path, rig, format="json", image_size=(640, 480))
    common = [
        "associate",
        "--rig",
        rig_path,
        "--points",
        points,
        "--sigma",
        "1",
        "--method",
        "paper",
    ]
    assert (
        main([*common, "--temporal-prior", "--track-step-px", "40", "--out", tmp_path / "a.json"])
        == 0
    )
    assert (
        "tracks: 2 over 3 frame(s); 0 point(s) recovered by the temporal prior"
        in capsys.readouterr().out
    )
    data = json.loads((tmp_path / "a.json").read_text())["frames"]
    # A track keeps its point: the first member's slot in view 0 swaps with the slots.
    track_of_slot = [
        {g["members"][0][1]: g["track"] for g in fr["groups"] if g["members"][0][0] == 0}
        for fr in data
    ]
    assert track_of_slot[0] == track_of_slot[2] == {0: track_of_slot[0][0], 1: track_of_slot[0][1]}
    assert track_of_slot[1] == {0: track_of_slot[0][1], 1: track_of_slot[0][0]}
    assert main([*common, "--out", tmp_path / "a.csv"]) == 0
    assert "recovered by the temporal prior" in capsys.readouterr().out  # on by default
    assert main([*common, "--no-temporal-prior"]) == 0
    assert "recovered by the temporal prior" not in capsys.readouterr().out
    with open(tmp_path / "a.csv") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert sorted({r["track"] for r in rows}) == ["0", "1"] and len(rows) == 6
    assert main([*common, "--out", tmp_path / "a.npz"]) == 0
    with np.load(tmp_path / "a.npz") as z:
        assert sorted(np.unique(z["track_id"][z["valid"]])) == [0, 1]
    # in parts of two frames (detections without classes, from one file): the same
    assert main([*common, "--part-frames", "2", "--out", tmp_path / "b.npz"]) == 0
    with np.load(tmp_path / "a.npz") as a, np.load(tmp_path / "b.npz") as b:
        for name in ("labels", "groups", "valid", "track_id", "recovered", "xy", "mask"):
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
        np.testing.assert_allclose(a["points3d"], b["points3d"], rtol=0, atol=1e-5)
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main([*common, "--track-step-px", "0"])
    assert "--track-step-px: must be a finite number > 0; got '0'" in capsys.readouterr().err


def test_the_prior_on_one_scene_says_it_does_nothing(tmp_path, capsys):
    rig = ring_rig(num_views=3)
    xy, _ = project_np(rig, np.array([[0.2, 0.0, 0.1], [-0.3, 0.2, 0.0]]))
    points, rig_path = tmp_path / "one.json", tmp_path / "rig.json"
    points.write_text(
        json.dumps({"views": [[[float(v) for v in p] for p in xy[m]] for m in range(3)]})
    )
    save_rig(rig_path, rig, format="json", image_size=(640, 480))
    assert (
        main(
            [
                "associate",
                "--rig",
                rig_path,
                "--points",
                points,
                "--sigma",
                "1",
                "--method",
                "paper",
                "--temporal-prior",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "--temporal-prior needs a sequence of frames" in text and "tracks:" not in text


def test_a_recording_in_parts_gives_the_whole_recordings_output(tmp_path, capsys, monkeypatch):
    """``--part-frames``: a recording associated, tracked and identified in parts, one after
    the other, writes what the whole at once writes: every group, label, track id and person
    (points within 1e-5, σ within its round-off; rows past the valid ones are padding)."""
    from cdog_jax.synthetic import DEFAULT_BOX, default_rig

    rig = default_rig(num_views=4)
    rng = np.random.default_rng(0)
    lo, hi = (np.asarray(b) for b in DEFAULT_BOX)
    joints = rng.uniform(lo + 0.3 * (hi - lo), hi - 0.3 * (hi - lo), (2, 17, 3))
    step = np.array([0.01, 0.0, 0.0]) * (hi - lo)
    for m in range(4):  # one OpenPose file per view and frame; each view numbers people its way
        (tmp_path / "pose" / f"cam{m}").mkdir(parents=True)
    for f in range(7):
        xy, _ = project_np(rig, (joints + f * step).reshape(-1, 3))
        xy = (xy + rng.normal(0.0, 0.5, xy.shape)).reshape(4, 2, 17, 2)
        seen = rng.random((4, 2, 17)) > 0.15  # some joints missed
        for m in range(4):
            people = np.concatenate([xy[m], np.full((2, 17, 1), 0.9)], axis=2) * seen[m][..., None]
            (tmp_path / "pose" / f"cam{m}" / f"{f:06d}_keypoints.json").write_text(
                json.dumps(
                    {
                        "people": [
                            {"pose_keypoints_2d": p.ravel().tolist()}
                            for p in people[[m % 2, 1 - m % 2]]
                        ]
                    }
                )
            )
    save_rig(tmp_path / "rig.json", rig, format="json")
    common = ["associate", "--rig", tmp_path / "rig.json", "--points", tmp_path / "pose"]
    assert main([*common, "--out", tmp_path / "whole.npz"]) == 0
    whole_text = capsys.readouterr().out
    import cdog_jax.cli._associate_command as command

    released = []  # between parts, the freed heap goes back to the system
    release = command.release_freed_memory
    monkeypatch.setattr(command, "release_freed_memory", lambda: released.append(release()))
    assert main([*common, "--part-frames", "3", "--out", tmp_path / "parts.npz"]) == 0
    assert len(released) == 3  # 7 frames: parts of 3, 3 and 1
    parts_text = capsys.readouterr().out
    for line in ("3D points:", "tracks:", "people:", "classes:"):
        assert [s for s in whole_text.splitlines() if line in s] == [
            s for s in parts_text.splitlines() if line in s
        ]
    # .npz, .csv, .json and .trc wait on disk part by part: the same rows as the whole at once
    for name in ("csv", "json", "trc"):
        assert main([*common, "--out", tmp_path / f"whole.{name}"]) == 0
        assert main([*common, "--part-frames", "3", "--out", tmp_path / f"parts.{name}"]) == 0
    capsys.readouterr()
    from cdog_jax.io import load_trc

    people = sorted(p.name for p in tmp_path.glob("whole_person*.trc"))
    assert len(people) >= 2
    assert sorted(p.name for p in tmp_path.glob("parts_person*.trc")) == [
        name.replace("whole", "parts") for name in people
    ]
    for name in people:  # one file per person, every frame a row
        a, b = load_trc(tmp_path / name), load_trc(tmp_path / name.replace("whole", "parts"))
        assert a.names == b.names and a.markers.shape == b.markers.shape and len(a.frame) == 7
        np.testing.assert_allclose(a.markers, b.markers, rtol=0, atol=1e-5)
    whole, parts = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("whole", "parts"))
    assert len(parts["frames"]) == 7 and sum(len(f["groups"]) for f in parts["frames"]) > 100
    _assert_near(whole, parts, "")
    tables = []
    for name in ("whole.csv", "parts.csv"):
        with open(tmp_path / name) as f:
            tables.append(list(csv.DictReader(line for line in f if not line.startswith("#"))))
    assert len(tables[0]) > 100 and len(tables[1]) == len(tables[0])
    for a, b in zip(*tables):
        exact = ("frame", "group", "n_views", "class", "track", "person")
        assert [a[k] for k in exact] == [b[k] for k in exact]
        near = ("x", "y", "z", "err_px")
        np.testing.assert_allclose(
            [float(a[k]) for k in near], [float(b[k]) for k in near], atol=1e-5
        )
    rows = {"groups": -1, "valid": False, "points3d": 0, "bpe": 0, "err_px": 0, "n_views": 0}
    rows |= {"group_class": -1, "track_id": -1, "recovered": False, "person_id": -1}
    rows |= {"mixed": False, "people_points": np.nan, "people_id": -1}
    rows |= {"people_merged": False, "people_split": False}
    with np.load(tmp_path / "whole.npz") as a, np.load(tmp_path / "parts.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        assert int(a["valid"].sum()) > 100 and (a["person_id"] >= 0).sum() > 100
        for name in a.files:
            x, y = a[name], b[name]
            if name in rows:  # the same rows, then padding
                n = min(x.shape[1], y.shape[1])
                for rest in (x[:, n:], y[:, n:]):
                    np.testing.assert_array_equal(rest, np.full_like(rest, rows[name]))
                x, y = x[:, :n], y[:, :n]
            if name in ("points3d", "bpe", "err_px", "people_points"):
                np.testing.assert_allclose(x, y, rtol=0, atol=1e-5, err_msg=name)
            elif name in ("sigma_px", "tau_px"):  # a part's σ fit: the same up to round-off
                np.testing.assert_allclose(x, y, rtol=1e-5, err_msg=name)
            else:
                np.testing.assert_array_equal(x, y, err_msg=name)


def _assert_near(a, b, where: str) -> None:
    """Two JSON values equal but for floats, within 1e-5 (points; σ within its round-off)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), where
        for key in a:
            _assert_near(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            _assert_near(x, y, f"{where}[{k}]")
    elif isinstance(a, float):
        assert isinstance(b, float) and abs(a - b) <= 1e-5 * max(1.0, abs(a)), where
    else:
        assert a == b, where


def test_a_recording_a_quarter_longer_than_a_part_stays_whole():
    from cdog_jax.cli._associate_command import PART_FRAMES, in_parts

    assert not in_parts(PART_FRAMES, PART_FRAMES)
    assert not in_parts(301, 300) and not in_parts(375, 300) and in_parts(376, 300)
    assert not in_parts(2, 2) and in_parts(3, 2)  # small parts: any frame more splits

"""`cdog-jax associate` on a sequence: every output carries the groups' track ids, and
``--temporal-prior`` / ``--track-step-px`` reach the tracking."""

import csv
import json

import numpy as np
import pytest
from helpers import project_np, ring_rig

from cdog_jax.cli import main
from cdog_jax.io import save_rig_json


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
    save_rig_json(rig_path, rig, image_size=(640, 480))
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
    save_rig_json(rig_path, rig, image_size=(640, 480))
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

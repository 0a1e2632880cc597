"""``cdog-jax demo --save-scene DIR`` writes files that ``cdog-jax associate`` reads, and
associating them gives the groups of associating the scene in memory; the detections writer
round-trips through the reader."""

import json

import jax
import numpy as np
import pytest

import cdog_jax
from cdog_jax.cli import main
from cdog_jax.io import load_detections, load_rig, save_detections_json
from cdog_jax.io._detections_out import detection_order
from cdog_jax.synthetic import default_rig, generate_scene


def test_save_scene_then_associate_round_trip(tmp_path, capsys):
    folder = tmp_path / "scene"
    assert (
        main(
            [
                "demo",
                "--points",
                "12",
                "--seed",
                "3",
                "--out",
                tmp_path / "d.png",
                "--save-scene",
                folder,
            ]
        )
        == 0
    )
    assert "cdog-jax associate --rig" in capsys.readouterr().out
    rig_file = load_rig(folder / "rig.json")
    assert rig_file.image_size == (640, 480)
    truth = json.loads((folder / "truth.json").read_text())

    groups_path = tmp_path / "groups.json"
    assert (
        main(
            [
                "associate",
                "--rig",
                folder / "rig.json",
                "--points",
                folder / "detections.json",
                "--sigma",
                "1",
                "--out",
                groups_path,
            ]
        )
        == 0
    )
    written = json.loads(groups_path.read_text())
    from_files = {
        frozenset((v, truth["views"][v][s]) for v, s, *_ in g["members"]) for g in written["groups"]
    }

    # The same scene in memory (the demo's defaults: paper(), σ = 1 px, capacity = points).
    rig = default_rig()
    scene = generate_scene(jax.random.PRNGKey(3), rig, 12, 1.0, capacity=12)
    result = cdog_jax.associate(rig, scene.xy, scene.mask, sigma=1.0)
    instance = np.asarray(scene.instance)
    groups = np.asarray(result.groups)[np.asarray(result.valid)]
    in_memory = {
        frozenset((m, int(instance[m, s])) for m, s in enumerate(g) if s >= 0) for g in groups
    }
    assert from_files == in_memory and len(in_memory) > 0
    np.testing.assert_allclose(
        truth["points3d"], np.asarray(scene.points3d)[: int(scene.num_points)], atol=1e-6
    )
    assert [len(v) for v in truth["views"]] == np.asarray(scene.mask).sum(axis=1).tolist()


def test_save_detections_json_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 400, (2, 3, 4, 2))  # 2 frames, 3 views, 4 slots
    mask = rng.random((2, 3, 4)) < 0.7
    mask[:, :, 0] = True
    conf = np.where(mask, rng.uniform(0.1, 1.0, mask.shape), 0.0)
    path = tmp_path / "det.json"
    save_detections_json(path, xy, mask, confidence=conf)
    det = load_detections(path)
    assert det.frames and det.xy.shape[:2] == (2, 3)
    order = detection_order(mask[1])
    for f in range(2):
        order = detection_order(mask[f])
        m, i = np.nonzero(mask[f])
        np.testing.assert_array_equal(
            det.xy[f][m, order[m, i]], xy[f][m, i]
        )  # exact: repr round trip
        np.testing.assert_array_equal(det.confidence[f][m, order[m, i]], conf[f][m, i])
        assert det.mask[f].sum() == mask[f].sum()
    save_detections_json(path, xy[0], mask[0])  # one scene: {"views": …}
    assert "frames" not in json.loads(path.read_text())


def test_save_detections_json_refuses_bad_input(tmp_path):
    xy = np.zeros((2, 3, 2))
    mask = np.ones((2, 3), bool)
    with pytest.raises(ValueError, match=r"xy must be \(M, P, 2\)"):
        save_detections_json(tmp_path / "a.json", xy[..., :1], mask)
    xy[1, 2] = np.nan
    with pytest.raises(ValueError, match="view 1, slot 2"):
        save_detections_json(tmp_path / "a.json", xy, mask)
    assert not (tmp_path / "a.json").exists()

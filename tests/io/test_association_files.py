"""Association results on disk (docs/ALGORITHM.md §11, docs/CONVENTIONS.md §3): JSON, NPZ and CSV written from a real
association read back equal, and every valid detection is listed exactly once."""

import csv
import json
import re
from types import SimpleNamespace

import jax
import numpy as np
import pytest

import cdog_jax
import cdog_jax.synthetic
from cdog_jax.io._association_files import (
    CSV_COLUMNS,
    CsvParts,
    JsonParts,
    association_records,
    load_association_json,
    save_association_csv,
    save_association_json,
    save_association_npz,
)


@pytest.fixture(scope="module")
def result():
    """One synthetic scene and its association (compiled once for the module)."""
    rig = cdog_jax.synthetic.default_rig()
    scene = cdog_jax.synthetic.generate_scene(jax.random.PRNGKey(0), rig, 12, 0.5, capacity=12)
    assoc = cdog_jax.associate(rig, scene.xy, scene.mask, sigma=0.5)
    assert int(assoc.num_groups) > 0
    return rig, np.asarray(scene.xy), np.asarray(scene.mask), assoc


def _nodes(records):
    """Every ``(view, slot)`` listed in groups and unassigned, with repeats."""
    nodes = [(r[0], r[1]) for g in records["groups"] for r in g["members"]]
    return nodes + [(r[0], r[1]) for r in records["unassigned"]]


def _check_scene(records, xy, mask, assoc):
    nodes = _nodes(records)
    assert len(nodes) == len(set(nodes)) == int(mask.sum())
    assert set(nodes) == {(int(m), int(i)) for m, i in np.argwhere(mask)}
    for r in [r for g in records["groups"] for r in g["members"]] + records["unassigned"]:
        assert r[2:4] == [float(xy[r[0], r[1], 0]), float(xy[r[0], r[1], 1])]
    valid = np.flatnonzero(np.asarray(assoc.valid))
    assert [g["id"] for g in records["groups"]] == valid.tolist()
    for g in records["groups"]:
        k = g["id"]
        assert g["point3d"] == np.asarray(assoc.points3d[k], np.float64).tolist()
        assert g["bpe_px2"] == float(assoc.bpe[k])
        assert "bpe_px" not in g  # one reprojection error: err_px
        assert g["err_px"] == float(assoc.err_px[k])
        assert g["n_views"] == int(assoc.n_views[k]) == len(g["members"])
        slots = np.asarray(assoc.groups[k])
        assert sorted((r[0], r[1]) for r in g["members"]) == [
            (m, int(slots[m])) for m in np.flatnonzero(slots >= 0)
        ]
    labels = np.asarray(assoc.labels)
    assert all(labels[m, i] == -1 for m, i, *_ in records["unassigned"])


def test_json_round_trip_lists_every_detection_once(result, tmp_path):
    _, xy, mask, assoc = result
    path = tmp_path / "assoc.json"
    save_association_json(path, assoc, xy, mask)
    records = load_association_json(path)
    assert records == association_records(assoc, xy, mask)
    _check_scene(records, xy, mask, assoc)
    assert records["sigma_px"] == float(assoc.sigma_px) and records["tau_px"] == float(assoc.tau_px)
    assert records["num_views"] == xy.shape[0] and records["capacity"] == xy.shape[1]


def test_json_batch_is_frames(result, tmp_path):
    _, xy, mask, assoc = result
    # A batch of two: the scene, and the scene with its last group dropped.
    # (Any object with the Association fields will do: the constructor checks one scene's shapes.)
    batch = SimpleNamespace(**{k: np.stack([np.asarray(v)] * 2) for k, v in vars(assoc).items()})
    batch.valid[1, int(assoc.num_groups) - 1] = False
    path = tmp_path / "assoc.json"
    save_association_json(path, batch, np.stack([xy, xy]), np.stack([mask, mask]))
    data = load_association_json(path)
    assert len(data["frames"]) == 2
    assert data["frames"][0] == association_records(assoc, xy, mask)
    n = int(assoc.num_groups)
    assert len(data["frames"][1]["groups"]) == n - 1
    dropped = data["frames"][0]["groups"][-1]["members"]
    assert [r for r in data["frames"][1]["unassigned"] if r in dropped] == sorted(dropped)
    assert len(_nodes(data["frames"][1])) == int(mask.sum())


def test_confidence_and_rig_columns(result):
    rig, xy, mask, assoc = result
    conf = np.where(mask, 0.75, 0.0)
    records = association_records(assoc, xy, mask, confidence=conf, rig=rig)
    assert all(len(r) == 5 and r[4] == 0.75 for g in records["groups"] for r in g["members"])
    assert all(len(r) == 5 for r in records["unassigned"])
    for g in records["groups"]:
        e = np.asarray(g["member_err_px"])
        assert len(e) == g["n_views"]
        # float64 reprojection here, float32 in the pipeline.
        np.testing.assert_allclose(e.mean(), g["err_px"], atol=1e-2)
        np.testing.assert_allclose(np.mean(e**2), g["bpe_px2"], atol=1e-2)


def test_npz_round_trip(result, tmp_path):
    _, xy, mask, assoc = result
    path = tmp_path / "assoc.npz"
    save_association_npz(path, assoc, xy=xy, mask=mask)
    with np.load(path) as npz:
        for k in (
            "labels",
            "groups",
            "valid",
            "points3d",
            "bpe",
            "err_px",
            "n_views",
            "num_groups",
            "sigma_px",
            "tau_px",
        ):
            np.testing.assert_array_equal(npz[k], np.asarray(getattr(assoc, k)))
        np.testing.assert_array_equal(npz["xy"], xy)
        np.testing.assert_array_equal(npz["mask"], mask)


def test_csv_one_row_per_point(result, tmp_path):
    assoc = result[3]
    path = tmp_path / "assoc.csv"
    save_association_csv(path, assoc)
    with open(path, newline="", encoding="utf-8") as f:
        note = f.readline()
        rows = list(csv.DictReader(f))
    assert note.startswith("#") and "err_px: mean reprojection distance" in note
    assert tuple(rows[0].keys()) == CSV_COLUMNS
    n = int(assoc.num_groups)
    assert len(rows) == n
    for row, g in zip(rows, np.flatnonzero(np.asarray(assoc.valid))):
        assert int(row["frame"]) == 0 and int(row["group"]) == g
        assert [float(row[c]) for c in "xyz"] == np.asarray(assoc.points3d[g], np.float64).tolist()
        assert float(row["err_px"]) == float(assoc.err_px[g])  # the same number as the CLI and JSON
        assert float(row["bpe_px2"]) == float(assoc.bpe[g])
        assert int(row["n_views"]) == int(assoc.n_views[g])


def test_mismatched_inputs_raise(result, tmp_path):
    _, xy, mask, assoc = result
    with pytest.raises(ValueError, match=re.escape("xy and mask must have shapes")):
        association_records(assoc, xy[:, :3], mask[:, :3])
    member = np.argwhere(np.asarray(assoc.labels) >= 0)[0]
    holes = mask.copy()
    holes[tuple(member)] = False
    with pytest.raises(
        ValueError, match="where mask is False; are assoc and xy from the same scene"
    ):
        association_records(assoc, xy, holes)
    path = tmp_path / "bad.json"
    path.write_text(
        json.dumps(
            {
                "groups": [{"members": [[0, 1, 2.0]], "point3d": [0, 0, 0], "n_views": 1}],
                "unassigned": [],
            }
        )
    )
    with pytest.raises(
        ValueError,
        match=re.escape(f"{path}, group 0, member 0: expected [view, slot, x, y(, confidence)]"),
    ):
        load_association_json(path)


def _frames_of(result, frames: slice):
    """A tracked result of frames cut to ``frames`` (as the command's parts are)."""
    fields = {}
    for name, value in result._asdict().items():
        if hasattr(value, "labels") and hasattr(value, "valid"):
            fields[name] = jax.tree_util.tree_map(lambda a: np.asarray(a)[frames], value)
        elif isinstance(value, (np.ndarray, jax.Array)) and value.ndim:
            fields[name] = np.asarray(value)[frames]
    return result._replace(**fields)


def test_json_and_csv_written_in_parts_are_the_whole_files(tmp_path):
    """A recording given to JsonParts / CsvParts a part at a time (one part empty) writes
    the bytes that save_association_json / save_association_csv write of the whole."""
    rig = cdog_jax.synthetic.default_rig(num_views=4)
    walk = cdog_jax.synthetic.generate_skeleton_scenes(
        jax.random.PRNGKey(1), rig, 2, 1.0, num_frames=5
    )
    xy, mask = np.asarray(walk.frames.xy, np.float32), np.asarray(walk.frames.mask)
    classes = np.where(mask, np.asarray(walk.frames.class_id), 0)
    tracked = cdog_jax.associate_sequence(rig, xy, mask, classes=classes)
    assert int(np.asarray(tracked.association.valid).sum()) > 20
    save_association_json(tmp_path / "whole.json", tracked, xy, mask, classes=classes)
    save_association_csv(tmp_path / "whole.csv", tracked)
    (tmp_path / "json").mkdir(), (tmp_path / "csv").mkdir()
    json_parts, csv_parts = JsonParts(str(tmp_path / "json")), CsvParts(str(tmp_path / "csv"))
    for frames in (slice(0, 2), slice(2, 2), slice(2, 3), slice(3, 5)):
        part = _frames_of(tracked, frames)
        json_parts.add(part, xy[frames], mask[frames], classes=classes[frames])
        csv_parts.add(part)
    json_parts.write(tmp_path / "parts.json")
    csv_parts.write(tmp_path / "parts.csv")
    for name in ("json", "csv"):
        whole = (tmp_path / f"whole.{name}").read_bytes()
        assert (tmp_path / f"parts.{name}").read_bytes() == whole, name
    assert len(load_association_json(tmp_path / "parts.json")["frames"]) == 5
    with pytest.raises(ValueError, match="a batch of frames"):
        json_parts.add(_frames_of(tracked, 0), xy[0], mask[0])

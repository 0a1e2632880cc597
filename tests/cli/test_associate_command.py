"""`cdog-jax associate` and `cdog-jax rig` end to end, in a temporary folder: a generated
rig written in every rig format, a detections file, association, output read back."""

import csv
import json
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import cdog_jax
from cdog_jax.cli import main
from cdog_jax.geometry import distort_pixels
from cdog_jax.io import load_association_json, save_rig
from cdog_jax.synthetic import IMAGE_SIZE, default_rig, generate_scene

SIGMA = 0.5
DIST = np.array([-0.2, 0.05, 5e-4, -5e-4, 0.0])


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """The default rig, one scene, its detections file (per-view lists, confidences), and
    the association of the same lists done in Python."""
    folder = tmp_path_factory.mktemp("associate_cli")
    rig = default_rig()
    scene = generate_scene(jax.random.PRNGKey(5), rig, 12, SIGMA, capacity=12)
    xy, mask = np.asarray(scene.xy, np.float64), np.asarray(scene.mask)
    conf = np.random.default_rng(0).uniform(0.5, 1.0, mask.shape)
    views = [
        [[*xy[m, i], conf[m, i]] for i in range(mask.shape[1]) if mask[m, i]]
        for m in range(mask.shape[0])
    ]
    points = folder / "detections.json"
    points.write_text(json.dumps({"views": views}))
    # The file's slots are the scene's detections packed to the front of each view.
    P = max(len(v) for v in views)
    xy_file = np.zeros((mask.shape[0], P, 2))
    mask_file = np.zeros((mask.shape[0], P), bool)
    for m, v in enumerate(views):
        xy_file[m, : len(v)] = np.asarray(v)[:, :2] if v else 0.0
        mask_file[m, : len(v)] = True
    expected = cdog_jax.associate(
        rig, jnp.asarray(xy_file, jnp.float32), jnp.asarray(mask_file), sigma=SIGMA
    )
    return folder, rig, points, views, expected


def _points(expected):
    n = int(expected.num_groups)
    return np.asarray(expected.points3d)[:n]


WRITERS = {
    "easyvis": lambda p, rig: save_rig(p, rig, format="easyvis"),
    "json": lambda p, rig: save_rig(p, rig, format="json", image_size=IMAGE_SIZE),
    "npz": lambda p, rig: save_rig(p, rig, format="npz", image_size=IMAGE_SIZE),
    "anipose": lambda p, rig: save_rig(p, rig, format="anipose", image_size=IMAGE_SIZE),
    "colmap": lambda p, rig: save_rig(p, rig, format="colmap", image_size=IMAGE_SIZE),
    "easymocap": lambda p, rig: save_rig(p, rig, format="easymocap"),
}
NAMES = {
    "easyvis": "rig_ev",
    "json": "rig.json",
    "npz": "rig.npz",
    "anipose": "calibration.toml",
    "colmap": "colmap",
    "easymocap": "easymocap",
}


@pytest.mark.parametrize("fmt", list(WRITERS))
def test_associate_from_every_rig_format(data, fmt, capsys):
    folder, rig, points, views, expected = data
    rig_path = folder / NAMES[fmt]
    WRITERS[fmt](rig_path, rig)
    out = folder / f"groups_{fmt}.json"
    assert (
        main(
            [
                "associate",
                "--rig",
                rig_path,
                "--points",
                points,
                "--sigma",
                str(SIGMA),
                "--out",
                out,
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert f"3D points: {int(expected.num_groups)}" in text
    records = load_association_json(out)
    got = np.array([g["point3d"] for g in records["groups"]])
    np.testing.assert_allclose(got, _points(expected), atol=1e-3)
    # Every detection of the file appears once, in a group or as unassigned.
    listed = [(r[0], r[1]) for g in records["groups"] for r in g["members"]] + [
        (r[0], r[1]) for r in records["unassigned"]
    ]
    assert sorted(listed) == sorted((m, i) for m, v in enumerate(views) for i in range(len(v)))


@pytest.mark.parametrize("shift", [1e6, 1e5])
def test_a_rig_far_from_its_world_origin_is_centred(data, shift, capsys):
    """A rig file in UTM-like coordinates (the world moved by 1e5–1e6 units): float32
    cannot hold it in its own world, so the command associates about the cameras' centre
    and writes the points in the file's world: the groups of the rig near its origin, every
    point the same one moved (npz: float64)."""
    folder, rig, points, views, expected = data
    offset = np.array([shift, 0.5 * shift, 10.0])
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    far = t - np.einsum("mij,j->mi", R, offset)  # X_cam = R (X_far - offset) + t
    rig_path = folder / f"far_rig_{shift:g}.json"
    rig_path.write_text(
        json.dumps(
            {
                "views": [
                    {"K": K[m].tolist(), "R": R[m].tolist(), "t": far[m].tolist()}
                    for m in range(len(K))
                ]
            }
        )
    )
    out = folder / f"far_{shift:g}.json"
    common = ["associate", "--rig", rig_path, "--points", points, "--sigma", str(SIGMA)]
    assert main([*common, "--out", out]) == 0
    text = capsys.readouterr().out
    assert "the cameras lie far from the rig's world origin" in text
    assert f"3D points: {int(expected.num_groups)}" in text
    records = load_association_json(out)
    got = np.array([g["point3d"] for g in records["groups"]], np.float64)
    np.testing.assert_allclose(got - offset, _points(expected), atol=1e-3)
    listed = [(r[0], r[1]) for g in records["groups"] for r in g["members"]]
    want = np.asarray(expected.groups)[: int(expected.num_groups)]
    assert sorted(listed) == sorted((m, int(i)) for g in want for m, i in enumerate(g) if i >= 0)
    assert main(["rig", rig_path]) == 0  # described about the cameras' centre, and said
    assert "described about their mean centre" in capsys.readouterr().out
    assert main([*common, "--out", folder / "far.npz"]) == 0
    with np.load(folder / "far.npz") as z:
        assert z["points3d"].dtype == np.float64
        np.testing.assert_allclose(z["points3d"][z["valid"]] - offset, _points(expected), atol=1e-3)


def test_associate_frames_csv_npz_weights_min_views_plot(data, capsys):
    folder, rig, points, views, expected = data
    rig_path = folder / "rig_frames.json"
    save_rig(rig_path, rig, format="json", image_size=IMAGE_SIZE)
    frames = folder / "frames.json"
    frames.write_text(json.dumps({"frames": [{"views": views}, {"views": views[::-1][::-1]}]}))
    out_csv, out_npz, fig = folder / "points.csv", folder / "groups.npz", folder / "frame0.png"
    common = ["associate", "--rig", rig_path, "--points", frames, "--sigma", str(SIGMA)]
    assert (
        main([*common, "--min-views", "3", "--confidence-weights", "--out", out_csv, "--plot", fig])
        == 0
    )
    text = capsys.readouterr().out
    assert "2 frame(s)" in text and fig.stat().st_size > 10_000
    with open(out_csv) as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    n3 = int((np.asarray(expected.n_views) >= 3)[: int(expected.num_groups)].sum())
    assert len(rows) == 2 * n3  # two identical frames
    assert all(int(r["n_views"]) >= 3 for r in rows)
    assert main([*common, "--out", out_npz]) == 0
    with np.load(out_npz) as npz:
        np.testing.assert_array_equal(npz["num_groups"], [int(expected.num_groups)] * 2)


def test_associate_summary_says_when_sigma_fell_back(data, capsys):
    folder, rig, points, views, expected = data
    rig_path = folder / "rig_fallback.json"
    save_rig(rig_path, rig, format="json", image_size=IMAGE_SIZE)
    # Frame 1: one detection in each of two views (of different points): nothing to estimate σ from.
    thin = [[[300.0, 200.0]], [[350.0, 260.0]]] + [[] for _ in views[2:]]
    frames = folder / "frames_fallback.json"
    frames.write_text(
        json.dumps({"frames": [{"views": [[r[:2] for r in v] for v in views]}, {"views": thin}]})
    )
    assert main(["associate", "--rig", rig_path, "--points", frames]) == 0
    text = capsys.readouterr().out
    assert (
        "(not estimated in 1 of 2 frame(s), e.g. frame 1: too little evidence to estimate σ, "
        "the fallback 1 px" in text
    )


def test_associate_undistorts_with_the_rig_distortion(data, capsys):
    folder, rig, points, views, expected = data
    dist = np.tile(DIST, (rig.num_views, 1))
    rig_path = folder / "lens.toml"
    save_rig(rig_path, rig, format="anipose", image_size=IMAGE_SIZE, dist=dist)
    lens_views = []
    for m, v in enumerate(views):
        if not v:
            lens_views.append([])
            continue
        xy = jnp.asarray(np.asarray(v)[None, :, :2], jnp.float32)
        d = distort_pixels(rig.K[m : m + 1], jnp.asarray(dist[m : m + 1], jnp.float32), xy)[0]
        lens_views.append(np.asarray(d, np.float64).tolist())
    lens_points = folder / "lens_detections.json"
    lens_points.write_text(json.dumps({"views": lens_views}))
    out = folder / "lens_groups.json"
    assert (
        main(
            [
                "associate",
                "--rig",
                rig_path,
                "--points",
                lens_points,
                "--sigma",
                str(SIGMA),
                "--out",
                out,
            ]
        )
        == 0
    )
    assert "with lens distortion" in capsys.readouterr().out
    got = np.array([g["point3d"] for g in load_association_json(out)["groups"]])
    np.testing.assert_allclose(got, _points(expected), atol=2e-3)


def test_rig_command_describes_and_plots(data, capsys):
    folder, rig, points, views, expected = data
    rig_path = folder / "described.json"
    save_rig(rig_path, rig, format="json", image_size=IMAGE_SIZE)
    fig = folder / "rig.png"
    assert main(["rig", rig_path, "--points", points, "--plot", fig]) == 0
    text = capsys.readouterr().out
    assert "baseline" in text.lower() and "No warnings." in text
    assert fig.stat().st_size > 10_000
    # A rig given camera→world (R transposed, t = centre) is flagged.
    wrong = cdog_jax.Rig(rig.K, jnp.swapaxes(rig.R, -1, -2), rig.centers)
    wrong_path = folder / "wrong.json"
    save_rig(wrong_path, wrong, format="json", image_size=IMAGE_SIZE)
    assert main(["rig", wrong_path, "--points", points]) == 0
    assert "camera→world" in capsys.readouterr().out


def test_associate_refuses_bad_input_before_any_work(data, tmp_path, capsys):
    folder, rig, points, views, expected = data
    rig_path = tmp_path / "three.json"
    save_rig(rig_path, rig.select([0, 1, 2]), format="json")
    assert main(["associate", "--rig", rig_path, "--points", points]) == 2
    assert re.search(
        r"^cdog-jax: error: .*detections\.json.*10 views; the rig has 3", capsys.readouterr().err
    )
    assert (
        main(["associate", "--rig", rig_path, "--points", points, "--out", tmp_path / "x.txt"]) == 2
    )
    assert "extension must be one of" in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"detections\.json.*10 views; the rig has 3"):
        main(["associate", "--debug", "--rig", rig_path, "--points", points])
    ten = tmp_path / "ten.json"
    save_rig(ten, rig, format="json")
    assert main(["associate", "--rig", ten, "--points", points, "--min-views", "11"]) == 2
    assert capsys.readouterr().err == (
        "cdog-jax: error: min_views must be at most the number of views, 10 "
        "(no group has more); got 11\n"
    )


def test_associate_with_the_robust_sigma_estimator(data, capsys):
    """``--sigma robust`` runs the chosen method with its heavy-tail σ estimator: the file's
    σ and groups are those of ``associate`` with ``sigma_mode="robust"``."""
    folder, rig, points, views, expected = data
    rig_path = folder / "rig_robust.json"
    save_rig(rig_path, rig, format="json", image_size=IMAGE_SIZE)
    out = folder / "robust.json"
    assert (
        main(
            ["associate", "--rig", rig_path, "--points", points, "--sigma", "robust", "--out", out]
        )
        == 0
    )
    assert "σ estimated (robust)" in capsys.readouterr().out
    P = max(len(v) for v in views)
    xy = np.zeros((len(views), P, 2), np.float32)
    mask = np.zeros((len(views), P), bool)
    for m, v in enumerate(views):
        xy[m, : len(v)] = np.asarray(v)[:, :2] if v else 0.0
        mask[m, : len(v)] = True
    robust = cdog_jax.associate(
        rig, xy, mask, method=cdog_jax.Config.best(sigma_mode="robust"), sigma="auto"
    )
    auto = cdog_jax.associate(rig, xy, mask, method=cdog_jax.Config.best(), sigma="auto")
    assert float(robust.sigma_px) != float(auto.sigma_px)
    records = load_association_json(out)
    np.testing.assert_allclose(records["sigma_px"], float(robust.sigma_px), rtol=1e-5)
    np.testing.assert_allclose(
        np.array([g["point3d"] for g in records["groups"]]), _points(robust), atol=1e-3
    )

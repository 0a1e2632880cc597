"""The command line never destroys data and never shows a traceback for a user error.

Every refusal here happens before any compilation: ``main`` returns 2 and prints one line
``cdog-jax: error: <file>: <what>`` (argparse's own usage errors raise ``SystemExit(2)``).
Two end-to-end runs associate a tiny three-view rig.
"""

import json
import os

import numpy as np
import pytest

from cdog_jax.cli import main
from cdog_jax.io import load_detections, save_rig
from cdog_jax.synthetic import IMAGE_SIZE, default_rig

RIG = default_rig().select([0, 1, 2])


def _project(X):
    """Pixels ``(M, n, 2)`` of world points ``X (n, 3)`` in the three views of ``RIG``."""
    K, R, t = (np.asarray(a, np.float64) for a in (RIG.K, RIG.R, RIG.t))
    h = np.einsum("mij,mnj->mni", K, np.einsum("mij,nj->mni", R, X) + t[:, None, :])
    return h[..., :2] / h[..., 2:]


POINTS3D = np.array([[0.0, 0.0, 0.5], [0.2, -0.1, 0.6], [-0.15, 0.1, 0.4], [0.1, 0.2, 0.7]])
VIEWS = [[[float(x), float(y)] for x, y in view] for view in _project(POINTS3D)]


@pytest.fixture
def files(tmp_path):
    """A JSON rig with image size, one without, a detections file and a results file."""
    rig = tmp_path / "rig.json"
    save_rig(rig, RIG, format="json", image_size=IMAGE_SIZE)
    bare = tmp_path / "bare.json"
    save_rig(bare, RIG, format="json")
    points = tmp_path / "points.json"
    points.write_text(json.dumps({"views": VIEWS}))
    return tmp_path, rig, bare, points


def refused(argv, capsys, *expected):
    """Run ``main(argv)``; it must refuse with one ``cdog-jax: error:`` line (or argparse's
    usage error) holding every string of ``expected``. Returns that line."""
    try:
        code = main(argv)
    except SystemExit as e:  # argparse: usage line(s), then "prog: error: …"
        code = e.code
        err = capsys.readouterr().err
        line = err.strip().splitlines()[-1]
        assert "error:" in line, err
    else:
        err = capsys.readouterr().err
        lines = err.strip().splitlines()
        assert len(lines) == 1, err
        line = lines[0]
        assert line.startswith("cdog-jax: error: "), err
    assert code == 2
    assert "Traceback" not in err
    for text in expected:
        assert str(text) in line, line
    return line


def _associate(rig, points, *more):
    return ["associate", "--rig", rig, "--points", points, "--sigma", "1", *more]


# --- outputs: never an input, checked before any work ----------------------------------


def test_out_equal_to_points_is_refused_and_the_detections_kept(files, capsys):
    folder, rig, _, points = files
    before = points.read_bytes()
    refused(_associate(rig, points, "--out", points), capsys, points, "--out", "--points")
    assert points.read_bytes() == before


def test_out_equal_to_points_through_another_spelling(files, capsys):
    folder, rig, _, points = files
    other = folder / "sub" / ".." / "points.json"
    (folder / "sub").mkdir()
    refused(_associate(rig, points, "--out", other), capsys, "--out", "--points")


def test_plot_equal_to_an_input_is_refused(files, capsys):
    folder, rig, _, points = files
    refused(_associate(rig, points, "--plot", folder / "rig.json"), capsys, "--plot")
    refused(["rig", rig, "--plot", rig], capsys, "--plot", rig)


def test_out_equal_to_the_rig_file(files, capsys):
    folder, rig, _, points = files
    before = rig.read_bytes()
    refused(_associate(rig, points, "--out", rig), capsys, "--out", "--rig")
    assert rig.read_bytes() == before


def test_out_equal_to_plot(files, capsys):
    folder, rig, _, points = files
    refused(
        _associate(rig, points, "--out", folder / "a.json", "--plot", folder / "a.json"),
        capsys,
        "--out",
        "--plot",
    )


def test_trc_of_one_scene_without_people_is_refused(files, capsys):
    folder, rig, _, points = files
    refused(
        _associate(rig, points, "--out", folder / "m.trc"),
        capsys,
        "m.trc",
        "sequence of frames or per-view people",
    )
    refused(_associate(rig, points, "--out", folder / "m.trc", "--units", "m m"), capsys, "--units")
    assert not (folder / "m.trc").exists()


def test_trc_of_a_sequence_has_one_marker_per_track(files, capsys):
    from cdog_jax.io import load_trc

    folder, rig, _, _ = files
    seq = folder / "seq.json"
    seq.write_text(json.dumps({"frames": [{"views": VIEWS}, {"views": VIEWS}]}))
    assert main(_associate(rig, seq, "--out", folder / "m.trc", "--fps", "50")) == 0
    assert "4 marker(s), one per track, 50 frames/s" in capsys.readouterr().out
    trc = load_trc(folder / "m.trc")
    assert trc.names == ("track0", "track1", "track2", "track3") and trc.rate == 50
    np.testing.assert_allclose(
        np.sort(trc.markers[0], axis=0), np.sort(POINTS3D, axis=0), atol=1e-4
    )
    # In parts (each part's markers wait on disk): the file of the whole at once.
    seq.write_text(json.dumps({"frames": [{"views": VIEWS}] * 5}))
    assert main(_associate(rig, seq, "--out", folder / "whole.trc")) == 0
    assert main(_associate(rig, seq, "--out", folder / "parts.trc", "--part-frames", "2")) == 0
    assert "4 marker(s), one per track" in capsys.readouterr().out
    whole, parts = load_trc(folder / "whole.trc"), load_trc(folder / "parts.trc")
    assert parts.names == whole.names and parts.markers.shape == (5, 4, 3)
    np.testing.assert_array_equal(parts.frame, whole.frame)
    np.testing.assert_allclose(parts.markers, whole.markers, rtol=0, atol=1e-5)


def test_out_in_a_missing_folder(files, capsys):
    folder, rig, _, points = files
    refused(
        _associate(rig, points, "--out", folder / "nope" / "out.json"),
        capsys,
        "nope",
        "does not exist",
    )


def test_out_is_a_directory(files, capsys):
    folder, rig, _, points = files
    (folder / "d.json").mkdir()
    refused(_associate(rig, points, "--out", folder / "d.json"), capsys, "d.json", "is a folder")


def test_out_folder_not_writable(files, capsys, monkeypatch):
    folder, rig, _, points = files
    (folder / "ro").mkdir()
    real = os.access
    monkeypatch.setattr(
        os,
        "access",
        lambda p, mode, **kw: False if os.fspath(p).endswith("ro") else real(p, mode, **kw),
    )
    refused(
        _associate(rig, points, "--out", folder / "ro" / "out.json"), capsys, "ro", "not writable"
    )


def test_out_existing_read_only_file(files, capsys, monkeypatch):
    folder, rig, _, points = files
    out = folder / "old.json"
    out.write_text("{}")
    real = os.access
    monkeypatch.setattr(
        os,
        "access",
        lambda p, mode, **kw: False if os.fspath(p).endswith("old.json") else real(p, mode, **kw),
    )
    refused(_associate(rig, points, "--out", out), capsys, "old.json", "read-only")


def test_out_read_only_by_its_mode_bits(files, capsys):
    """A file no one may write is kept, also when the user is root (who may write anyway)."""
    folder, rig, _, points = files
    out = folder / "kept.json"
    out.write_text("{}")
    out.chmod(0o444)
    refused(_associate(rig, points, "--out", out), capsys, "kept.json", "read-only")
    assert out.read_text() == "{}"


def test_dangling_links_and_views_out_of_range_refused_before_work(files, capsys):
    folder, rig, _, points = files
    link = folder / "gone.json"
    link.symlink_to(folder / "missing" / "x.json")
    refused(_associate(rig, points, "--out", link), capsys, "gone.json", "symbolic link")
    out = folder / "results"
    out.symlink_to(folder / "missing")
    bench = ["benchmark", "--quick", "--no-figures", "--no-progress"]
    refused([*bench, "--out", out], capsys, "results", "symbolic link")
    line = refused([*bench, "--out", folder / "b", "--views", "0", "1", "99"], capsys, "99")
    assert "out of range" in line and not (folder / "b").exists()


def test_a_rig_written_camera_to_world_is_refused_by_every_command(tmp_path, capsys):
    """The same rig with R, t inverted (camera→world): `associate` (judged on the
    detections) and `track` (on where the optical axes meet) refuse it before any work."""
    import jax

    from cdog_jax.geometry import rig_from_arrays
    from cdog_jax.io import save_detections_json
    from cdog_jax.synthetic import generate_scene

    scene = generate_scene(jax.random.PRNGKey(0), RIG, 12, 1.0, capacity=12)
    points = tmp_path / "det.json"
    save_detections_json(points, np.asarray(scene.xy), np.asarray(scene.mask))
    R_inv = np.swapaxes(np.asarray(RIG.R), 1, 2)
    t_inv = -np.einsum("mij,mj->mi", R_inv, np.asarray(RIG.t))
    rig = tmp_path / "c2w.json"
    save_rig(
        rig, rig_from_arrays(np.asarray(RIG.K), R_inv, t_inv), format="json", image_size=IMAGE_SIZE
    )
    refused(_associate(rig, points), capsys, "c2w.json", "camera→world")
    refused(["track", "--rig", rig], capsys, "c2w.json", "camera→world")


def test_save_scene_replaces_nothing_unless_forced(tmp_path, capsys):
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "rig.json").write_text("mine")
    demo = ["demo", "--points", "5", "--out", tmp_path / "d.png", "--save-scene", folder]
    line = refused(demo, capsys, "rig.json", "already there", "--force")
    assert (folder / "rig.json").read_text() == "mine" and not (tmp_path / "d.png").exists()
    (folder / "truth.json").write_text("{}")
    (folder / "truth.json").chmod(0o444)
    refused([*demo, "--force"], capsys, "truth.json", "read-only")
    (folder / "truth.json").chmod(0o644)
    assert main([*demo, "--force"]) == 0
    assert (folder / "rig.json").read_text() != "mine" and line


def test_out_and_plot_extensions(files, capsys):
    folder, rig, _, points = files
    refused(_associate(rig, points, "--out", folder / "x.txt"), capsys, "x.txt", ".json")
    refused(_associate(rig, points, "--plot", folder / "x.xyz"), capsys, "x.xyz", ".png")


def test_other_commands_check_their_outputs(files, capsys):
    folder, rig, _, points = files
    refused(["demo", "--out", folder / "nope" / "d.png"], capsys, "nope", "does not exist")
    refused(["demo", "--out", folder / "d.txt"], capsys, "d.txt", ".png")
    refused(
        ["calibrate", "--quick", "--out", folder / "nope" / "c.png"],
        capsys,
        "nope",
        "does not exist",
    )
    (folder / "file").write_text("x")
    refused(["benchmark", "--quick", "--out", folder / "file"], capsys, "file", "not a folder")
    (folder / "bench").mkdir()
    (folder / "bench" / "results.json").write_bytes(rig.read_bytes())
    rig_in_out = folder / "bench" / "results.json"
    refused(
        ["benchmark", "--quick", "--rig", rig_in_out, "--out", folder / "bench"],
        capsys,
        "--out",
        "results.json",
        "--rig",
    )
    refused(["rig", rig, "--plot", folder / "nope" / "r.png"], capsys, "nope", "does not exist")


# --- inputs: one line naming the file ---------------------------------------------------


def test_points_not_utf8(files, capsys):
    folder, rig, _, points = files
    points.write_bytes(b'{"views": [[[1, 2]], [[3, 4]]], "note": "caf\xe9"}')
    refused(_associate(rig, points), capsys, points, "UTF-8", "byte 44")


def test_rig_not_utf8(files, capsys):
    folder, rig, _, points = files
    rig.write_bytes(b'{"views": "\xff"}')
    refused(_associate(rig, points), capsys, rig, "UTF-8", "byte 11")
    toml = folder / "calibration.toml"
    toml.write_bytes(b'[cam_0]\nname = "\xff"\n')
    refused(_associate(toml, points), capsys, toml, "UTF-8", "byte 16")
    (folder / "ev").mkdir()
    for letter in "KRT":
        (folder / "ev" / f"{letter}0.txt").write_bytes(b"[\xfe]")
    refused(_associate(folder / "ev", points), capsys, "K0.txt", "UTF-8", "byte 1")


def test_huge_integer(files, capsys):
    folder, rig, _, points = files
    views = [[[int("9" * 400), 2]], [[3, 4]], [[5, 6]]]
    points.write_text(json.dumps({"views": views}))
    refused(_associate(rig, points), capsys, points, "view 0, detection 0", "too large")
    points.write_text('{"views": [[[' + "9" * 5000 + ", 2]], [[3, 4]]]}")
    refused(_associate(rig, points), capsys, points, "5000 digits")
    data = json.loads(rig.read_text())
    data["views"][1]["K"][0][0] = int("9" * 400)
    rig.write_text(json.dumps(data))
    refused(_associate(rig, points), capsys, rig, 'view 1, key "K"', "too large")


def test_deep_nesting(files, capsys):
    folder, rig, _, points = files
    points.write_text('{"views": ' + "[" * 100_000 + "]" * 100_000 + "}")
    refused(_associate(rig, points), capsys, points, "nested too deeply")
    rig.write_text("[" * 100_000 + "]" * 100_000)
    refused(_associate(rig, points), capsys, rig, "nested too deeply")


def test_missing_paths_and_folders_where_files_belong(files, capsys):
    folder, rig, _, points = files
    refused(
        _associate(rig, folder / "missing.json"),
        capsys,
        "missing.json",
        "--points",
        "does not exist",
    )
    refused(
        _associate(folder / "missing_rig.json", points),
        capsys,
        "missing_rig.json",
        "--rig",
        "does not exist",
    )
    (folder / "dir.json").mkdir()
    refused(_associate(rig, folder / "dir.json"), capsys, "dir.json", "is a folder")
    refused(_associate(folder / "dir.json", points), capsys, "dir.json", "is a folder")
    refused(
        ["associate", "--rig", rig, "--rig-format", "easyvis", "--points", points],
        capsys,
        rig,
        "not a folder",
    )
    refused(["rig", folder / "missing_rig"], capsys, "missing_rig", "does not exist")
    refused(
        ["benchmark", "--rig", folder / "missing_rig", "--out", folder / "b"],
        capsys,
        "missing_rig",
        "does not exist",
    )


def test_invalid_json_is_one_line(files, capsys):
    folder, rig, _, points = files
    points.write_text('{"views": [')
    refused(_associate(rig, points), capsys, points, "not valid JSON")


def test_npz_object_arrays(files, capsys):
    folder, rig, _, points = files
    det = folder / "points.npz"
    xy = np.empty((3, 1, 2), object)
    xy[...] = 1.0
    np.savez(det, xy=xy, mask=np.ones((3, 1), bool))
    refused(_associate(rig, det), capsys, det, '"xy"', "Python objects")
    rig_npz = folder / "rig.npz"
    K = np.asarray(RIG.K, np.float64).astype(object)
    np.savez(rig_npz, K=K, R=np.asarray(RIG.R), t=np.asarray(RIG.t))
    refused(_associate(rig_npz, points), capsys, rig_npz, '"K"', "Python objects")


def test_coordinate_out_of_float32_range(files, capsys):
    folder, rig, bare, points = files
    views = json.loads(json.dumps(VIEWS))
    views[2][1][0] = 1e39
    points.write_text(json.dumps({"views": views}))
    refused(_associate(bare, points), capsys, points, "view 2, detection 1", "float32")


def test_rig_number_out_of_float32_range(files, capsys):
    folder, rig, _, points = files
    data = json.loads(rig.read_text())
    data["views"][1]["t"][0] = 1e39
    rig.write_text(json.dumps(data))
    refused(["rig", rig], capsys, rig, "view 1", "t has entries out of float32 range", "1e+39")


def test_detections_refusals_name_the_file(files, capsys):
    folder, rig, _, points = files
    points.write_text(json.dumps({"views": VIEWS[:2]}))
    refused(_associate(rig, points), capsys, points, "2 views", "3")
    points.write_text(json.dumps({"views": [[[1, 2, 1.5]], [[3, 4, 0.5]], []]}))
    refused(_associate(rig, points), capsys, points, "view 0, detection 0", "1.5")


# --- σ and the other numbers of the command line ----------------------------------------


@pytest.mark.parametrize("sigma", ["inf", "nan", "-1", "1e39"])
def test_sigma_not_finite_or_huge(files, capsys, sigma):
    folder, rig, _, points = files
    refused(["associate", "--rig", rig, "--points", points, "--sigma", sigma], capsys, "--sigma")


def test_sigma_larger_than_the_image_diagonal(files, capsys):
    folder, rig, bare, points = files
    refused(
        ["associate", "--rig", rig, "--points", points, "--sigma", "900"],
        capsys,
        "--sigma",
        "800",
        "diagonal",
    )
    # Without an image size: twice the principal point (320.8, 240.7) → about 802 px.
    refused(
        ["associate", "--rig", bare, "--points", points, "--sigma", "900"],
        capsys,
        "--sigma",
        "diagonal",
    )
    refused(["demo", "--sigma", "inf"], capsys, "--sigma")
    refused(["demo", "--sigma", "5000"], capsys, "--sigma", "diagonal")
    refused(["calibrate", "--sigma", "nan"], capsys, "--sigma")
    refused(["benchmark", "--sigmas", "1", "inf"], capsys, "--sigmas")


def test_other_numbers(files, capsys):
    folder, rig, _, points = files
    refused(_associate(rig, points, "--batch-size", "0"), capsys, "--batch-size")
    refused(_associate(rig, points, "--capacity", "0"), capsys, "--capacity")
    refused(["benchmark", "--counts", "-3"], capsys, "--counts")
    refused(["benchmark", "--scenes", "0"], capsys, "--scenes")
    refused(["calibrate", "--rounds", "0"], capsys, "--rounds")


def test_debug_shows_the_traceback(files):
    folder, rig, _, points = files
    with pytest.raises(ValueError, match="--out"):
        main(["--debug", *_associate(rig, points, "--out", points)])


# --- frames without a possible group, detector scores above 1 ---------------------------


def test_frames_with_empty_or_single_views_are_noted_not_refused(tmp_path):
    frames = [{"views": VIEWS}, {"views": [[], [], []]}, {"views": [VIEWS[0], [], []]}]
    path = tmp_path / "frames.json"
    path.write_text(json.dumps({"frames": frames}))
    det = load_detections(path, num_views=3)
    assert det.mask.shape[0] == 3 and not det.mask[1].any()
    assert any("frames 1, 2" in n and "zero groups" in n for n in det.notes), det.notes
    # A single scene, or a file none of whose frames can give a group, is still refused.
    path.write_text(json.dumps({"frames": frames[1:]}))
    with pytest.raises(ValueError, match="no frame has detections in 2 views"):
        load_detections(path)
    path.write_text(json.dumps({"views": [VIEWS[0], [], []]}))
    with pytest.raises(ValueError, match="association needs at least 2"):
        load_detections(path)


def test_scores_slightly_above_one_are_clipped_with_a_note(tmp_path):
    views = [[[x, y, 1.04] for x, y in v] for v in VIEWS]
    path = tmp_path / "openpose.json"
    path.write_text(json.dumps({"views": views}))
    det = load_detections(path)
    assert det.confidence.max() == 1.0
    assert any("above 1" in n and "clipped" in n for n in det.notes), det.notes
    views[1][2][2] = 1.2
    path.write_text(json.dumps({"views": views}))
    with pytest.raises(ValueError, match=r"view 1, detection 2: confidence 1\.2"):
        load_detections(path)


def test_associate_end_to_end_with_empty_frames(files, capsys):
    """Runs the association: frames 1 and 2 give no group, the summary says why, and the
    previous --out file is replaced whole."""
    folder, rig, _, points = files
    frames = [{"views": VIEWS}, {"views": [[], [], []]}, {"views": [VIEWS[0], [], []]}]
    points.write_text(json.dumps({"frames": frames}))
    out = folder / "out.json"
    out.write_text("old")
    # paper(): on three frames of three views, the program the track tests compile.
    assert main(_associate(rig, points, "--method", "paper", "--out", out)) == 0
    text = capsys.readouterr().out
    assert "zero groups" in text, text
    result = json.loads(out.read_text())
    assert [len(f["groups"]) for f in result["frames"]] == [4, 0, 0]
    assert sorted(os.listdir(folder)) == ["bare.json", "out.json", "points.json", "rig.json"]


def test_sigma_robust_for_a_method_without_that_estimator(files, capsys):
    folder, rig, _, points = files
    refused(
        ["associate", "--rig", rig, "--points", points, "--sigma", "median"],
        capsys,
        "--sigma",
        "robust",
    )

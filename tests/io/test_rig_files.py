"""Rig files (docs/CONVENTIONS.md §3): exact round trips, hand-written files project as computed by hand,
and every error names the file, the view and the key."""

import json
import re

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import x64

import cdog_jax
from cdog_jax.geometry import rig_from_arrays
from cdog_jax.io import RigFile, load_rig, save_rig
from cdog_jax.synthetic import default_rig
from cdog_jax.synthetic._rig import negate_intrinsics

# Two hand-made views: view 0 at (0, 0, -5) looking along +z; view 1 turned 90° about y,
# with a skewed K stored negated (K[2,2] = -1, as OpenMVG/EasyVis exports).
K0 = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]
K1 = [[-1000.0, -2.0, -300.0], [0.0, -900.0, -200.0], [0.0, 0.0, -1.0]]
R0 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
R1 = [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]
T = [0.0, 0.0, 5.0]
X_WORLD = [0.5, -0.25, 1.0]
# By hand: X_cam0 = (0.5, -0.25, 6); X_cam1 = R1 X + t = (-1, -0.25, 5.5), K1 → -K1.
XY_EXPECTED = [
    [320.0 + 800.0 * 0.5 / 6.0, 240.0 - 800.0 * 0.25 / 6.0],
    [300.0 + (1000.0 * -1.0 + 2.0 * -0.25) / 5.5, 200.0 - 900.0 * 0.25 / 5.5],
]


def _write(path, text):
    path.write_text(text, encoding="utf-8")
    return path


def _easyvis_folder(tmp_path, indices=(0, 1), skip=()):
    """The hand-made rig as an EasyVis folder (T0 as a column, T1 flat), with a P0.txt;
    hand view k is written under file index ``indices[k]``."""
    folder = tmp_path / "rig"
    folder.mkdir()
    files = [
        {
            "K": "[[800, 0, 320], [0, 800, 240], [0, 0, 1]]\n",
            "R": "[[1, 0, 0],\n [0, 1, 0],\n [0, 0, 1]]\n",
            "T": "[[0], [0], [5.0]]\n",
            "P": "not a literal at all\n",
        },
        {
            "K": "[[-1000.0, -2.0, -300.0], [0.0, -900.0, -200.0], [0.0, 0.0, -1.0]]",
            "R": "[[0, 0, -1], [0, 1, 0], [1, 0, 0]]",
            "T": "[0.0, 0.0, 5.0]",
        },
    ]
    for i, view in zip(indices, files):
        for letter, text in view.items():
            if f"{letter}{i}.txt" not in skip:
                _write(folder / f"{letter}{i}.txt", text)
    return folder


def _json_views():
    return [
        {"K": K0, "R": R0, "t": T, "image_size": [640, 480], "dist": [0.1, -0.2, 0.0, 0.001, 0.05]},
        {"K": K1, "R": R1, "t": [[0.0], [0.0], [5.0]], "image_size": [640, 480]},
    ]


def _json_file(tmp_path, views=None, name="rig.json"):
    return _write(tmp_path / name, json.dumps({"views": _json_views() if views is None else views}))


def _npz_file(tmp_path, name="rig.npz", **override):
    arrays = {
        "K": np.array([K0, K1]),
        "R": np.array([R0, R1]),
        "t": np.array([T, T]),
        "image_size": np.array([640, 480]),
    }
    arrays.update(override)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    path = tmp_path / name
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


def _assert_projects_by_hand(loaded):
    xy, ok = cdog_jax.project(loaded.rig, jnp.asarray(X_WORLD, loaded.rig.K.dtype))
    assert np.all(np.asarray(ok))
    np.testing.assert_allclose(np.asarray(xy, np.float64), XY_EXPECTED, atol=1e-3)


# Readers on hand-written files ----------------------------------------------------------


def test_easyvis_projects_as_by_hand(tmp_path):
    loaded = load_rig(_easyvis_folder(tmp_path))
    assert isinstance(loaded, RigFile) and loaded.image_size is None
    np.testing.assert_array_equal(loaded.dist, np.zeros((2, 5)))  # no distortion in the file: zeros
    assert loaded.rig.K.shape == (2, 3, 3) and loaded.rig.K.dtype == jnp.asarray(0.0).dtype
    assert float(loaded.rig.K[1, 2, 2]) == -1.0  # K kept as written
    _assert_projects_by_hand(loaded)


def test_json_projects_as_by_hand(tmp_path):
    loaded = load_rig(_json_file(tmp_path))
    assert loaded.image_size == (640, 480)
    # View 1 gives no dist: zeros.
    np.testing.assert_array_equal(loaded.dist, [[0.1, -0.2, 0.0, 0.001, 0.05], [0.0] * 5])
    assert loaded.dist.dtype == np.float64
    _assert_projects_by_hand(loaded)


def test_npz_projects_as_by_hand(tmp_path):
    loaded = load_rig(_npz_file(tmp_path))
    assert loaded.image_size == (640, 480) and not np.any(loaded.dist)
    _assert_projects_by_hand(loaded)


def test_explicit_format_overrides_suffix(tmp_path):
    path = _write(tmp_path / "rig.txt", json.dumps({"views": _json_views()}))
    _assert_projects_by_hand(load_rig(path, format="json"))


# Writers: exact round trips -------------------------------------------------------------

RIGS = {
    "default": lambda: default_rig(),
    "negated": lambda: negate_intrinsics(default_rig(), np.arange(10)),
}


def _save(fmt, tmp_path, rig, **extra):
    if fmt == "easyvis":
        path = tmp_path / "easyvis"
        save_rig(path, rig, format="easyvis")
    else:
        path = tmp_path / f"rig.{fmt}"
        save_rig(path, rig, format=fmt, **extra)
    return path


def _assert_same_rig(a, b):
    for x, y in ((a.K, b.K), (a.R, b.R), (a.t, b.t)):
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("which", sorted(RIGS))
@pytest.mark.parametrize("fmt", ["json", "npz", "easyvis"])
def test_round_trip_is_exact(tmp_path, fmt, which):
    rig = RIGS[which]()
    loaded = load_rig(_save(fmt, tmp_path, rig))
    _assert_same_rig(loaded.rig, rig)
    assert (
        loaded.image_size is None
        and loaded.dist.shape == (rig.num_views, 5)
        and not np.any(loaded.dist)
    )


@pytest.mark.parametrize("fmt", ["json", "npz"])
def test_round_trip_image_size_and_dist(tmp_path, fmt):
    rig = default_rig(num_views=3)
    dist = np.random.default_rng(0).normal(size=(3, 5)) * 0.1
    loaded = load_rig(_save(fmt, tmp_path, rig, image_size=(1920, 1080), dist=dist))
    assert loaded.image_size == (1920, 1080)
    np.testing.assert_array_equal(loaded.dist, dist)
    _assert_same_rig(loaded.rig, rig)


@pytest.mark.parametrize("fmt", ["json", "npz", "easyvis"])
def test_round_trip_is_exact_in_float64(tmp_path, fmt):
    rng = np.random.default_rng(1)
    base = negate_intrinsics(default_rig(num_views=3), [1])
    with x64():
        # Values with float64 mantissas that float32 would round.
        K = np.asarray(base.K, np.float64) * (1 + 1e-9 * rng.normal(size=(3, 1, 1)))
        t = np.asarray(base.t, np.float64) + 1e-10 * rng.normal(size=(3, 3))
        R = np.asarray(base.R, np.float64)
        rig = rig_from_arrays(K, R, t)
        assert rig.K.dtype == jnp.float64
        loaded = load_rig(_save(fmt, tmp_path, rig))
        _assert_same_rig(loaded.rig, rig)


def test_writer_rejects_bad_dist_and_stale_easyvis_files(tmp_path):
    rig = default_rig(num_views=2)
    with pytest.raises(
        ValueError, match=re.escape("dist must have shape (M, 5) = (2, 5); got (2, 4)")
    ):
        save_rig(tmp_path / "rig.json", rig, format="json", dist=np.zeros((2, 4)))
    save_rig(tmp_path / "ev", default_rig(num_views=3), format="easyvis")
    with pytest.raises(ValueError, match="K2.txt, beyond the 2 views"):
        save_rig(tmp_path / "ev", rig, format="easyvis")


# Errors name the file, the view and the key ---------------------------------------------


def _raises(path, *fragments):
    pattern = re.escape(str(path)) + ".*" + ".*".join(re.escape(f) for f in fragments)
    return pytest.raises(ValueError, match=pattern)


def test_easyvis_missing_file(tmp_path):
    folder = _easyvis_folder(tmp_path, skip=("T1.txt",))
    with _raises(folder, "missing T1.txt"):
        load_rig(folder)


def test_easyvis_gap_in_indices(tmp_path):
    folder = _easyvis_folder(tmp_path, indices=(0, 2))
    assert sorted(p.name for p in folder.iterdir()) == [
        "K0.txt",
        "K2.txt",
        "P0.txt",
        "R0.txt",
        "R2.txt",
        "T0.txt",
        "T2.txt",
    ]
    with _raises(folder, "missing K1.txt", "[0, 2]"):
        load_rig(folder)


def test_easyvis_zero_views(tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    _write(folder / "P0.txt", "[]")
    with _raises(folder, "zero views"):
        load_rig(folder)


@pytest.mark.parametrize(
    "text",
    ["[[1, 0, 0], [0, 1", "__import__('os').getcwd()", "[[1, 0, 0], [0, 1, 0], [0, 0, nan]]"],
)
def test_easyvis_bad_literal(tmp_path, text):
    folder = _easyvis_folder(tmp_path)
    _write(folder / "R1.txt", text)
    with _raises(folder / "R1.txt", "not a Python literal"):
        load_rig(folder)


def test_easyvis_strings_are_not_numbers(tmp_path):
    folder = _easyvis_folder(tmp_path)
    _write(folder / "T0.txt", "['0', 0, 5]")
    with _raises(folder / "T0.txt", "expected a nested list of numbers"):
        load_rig(folder)


def test_easyvis_wrong_shape(tmp_path):
    folder = _easyvis_folder(tmp_path)
    _write(folder / "K1.txt", "[[1, 0, 0], [0, 1, 0]]")
    with _raises(folder / "K1.txt", "expected shape (3, 3); got (2, 3)"):
        load_rig(folder)
    _write(folder / "K1.txt", "[[1, 0, 0], [0, 1, 0], [0, 0]]")
    with _raises(folder / "K1.txt", "ragged"):
        load_rig(folder)


def test_easyvis_non_finite(tmp_path):
    folder = _easyvis_folder(tmp_path)
    _write(folder / "T1.txt", "[0.0, 1e999, 5.0]")
    with _raises(folder / "T1.txt", "non-finite"):
        load_rig(folder)


def test_easyvis_singular_K(tmp_path):
    folder = _easyvis_folder(tmp_path)
    _write(folder / "K1.txt", "[[800, 0, 320], [0, 0, 0], [0, 0, 1]]")
    with _raises(folder, "K of view 1 is singular"):
        load_rig(folder)


def test_easyvis_not_a_rotation(tmp_path):
    folder = _easyvis_folder(tmp_path)
    _write(folder / "R0.txt", "[[1, 0, 0], [0, 1, 0], [0, 0, -1]]")
    with _raises(folder, "R of view 0 is not a rotation"):
        load_rig(folder)


def test_json_missing_key(tmp_path):
    views = _json_views()
    del views[1]["R"]
    path = _json_file(tmp_path, views)
    with _raises(path, "view 1", 'missing key "R"'):
        load_rig(path)
    path = _write(tmp_path / "cams.json", json.dumps({"cameras": []}))
    with _raises(path, 'missing key "views"'):
        load_rig(path)


def test_json_wrong_shape(tmp_path):
    views = _json_views()
    views[1]["t"] = [0.0, 5.0]
    path = _json_file(tmp_path, views)
    with _raises(path, 'view 1, key "t"', "expected shape (3,) or (3, 1); got (2,)"):
        load_rig(path)


def test_json_non_finite(tmp_path):
    path = _write(
        tmp_path / "rig.json", json.dumps({"views": _json_views()}).replace("800.0", "NaN", 1)
    )
    with _raises(path, 'view 0, key "K"', "non-finite"):
        load_rig(path)


def test_json_bad_image_size_and_dist(tmp_path):
    views = _json_views()
    views[1]["image_size"] = [1280, 720]
    path = _json_file(tmp_path, views)
    with _raises(path, "different", "image_size"):
        load_rig(path)
    views = _json_views()
    views[0]["dist"] = [0.1, 0.2]
    path = _json_file(tmp_path, views, name="rig2.json")
    with _raises(path, 'view 0, key "dist"', "expected shape (5,); got (2,)"):
        load_rig(path)


def test_json_not_json_and_singular_K(tmp_path):
    path = _write(tmp_path / "broken.json", '{"views": [')
    with _raises(path, "not valid JSON"):
        load_rig(path)
    views = _json_views()
    views[0]["K"] = [[0.0, 0.0, 0.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]
    path = _json_file(tmp_path, views)
    with _raises(path, "K of view 0 is singular"):
        load_rig(path)


def test_npz_errors(tmp_path):
    path = _npz_file(tmp_path, "missing.npz", t=None)
    with _raises(path, 'missing array "t"'):
        load_rig(path)
    path = _npz_file(tmp_path, "shape.npz", R=np.zeros((3, 3, 3)))
    with _raises(path, 'array "R"', "expected shape (2, 3, 3)", "got (3, 3, 3)"):
        load_rig(path)
    path = _npz_file(tmp_path, "inf.npz", t=np.array([T, [0.0, np.inf, 5.0]]))
    with _raises(path, 'array "t", view 1', "non-finite"):
        load_rig(path)
    path = _npz_file(tmp_path, "size.npz", image_size=np.array([640.5, 480.0]))
    with _raises(path, 'array "image_size"', "two positive integers"):
        load_rig(path)
    path = _npz_file(tmp_path, "singular.npz", K=np.array([K0, np.zeros((3, 3))]))
    with _raises(path, "K of view 1 is singular"):
        load_rig(path)
    path = _npz_file(tmp_path, "half.npz", t=np.array([T, T], np.float16))
    with _raises(path, 'array "t" has dtype float16, too coarse for a camera'):
        load_rig(path)


def test_unknown_format(tmp_path):
    path = _write(tmp_path / "rig.yaml", "views: []")
    with _raises(path, "cannot tell the rig format", "easyvis", ".json", ".npz"):
        load_rig(path)
    with _raises(path, "unknown rig format 'xml'", "'easyvis', 'json', 'npz'"):
        load_rig(path, format="xml")
    with _raises(path, "not a folder"):
        load_rig(path, format="easyvis")


def test_save_rig_tells_the_format_from_the_path_and_refuses_what_it_cannot_hold(tmp_path):
    """``save_rig`` writes by suffix (``transforms.json`` is nerfstudio), needs the format of a
    folder, and refuses an option the format cannot hold or a needed one missing: nothing
    given is silently left out."""
    rig = default_rig()
    save_rig(tmp_path / "rig.json", rig, image_size=(640, 480))
    save_rig(tmp_path / "rig.npz", rig)
    save_rig(tmp_path / "calibration.toml", rig, image_size=(640, 480), names=list("abcdefghij"))
    save_rig(tmp_path / "transforms.json", rig, image_size=(640, 480))
    assert load_rig(tmp_path / "rig.json").image_size == (640, 480)
    assert load_rig(tmp_path / "rig.npz").image_size is None
    assert load_rig(tmp_path / "calibration.toml").names == tuple("abcdefghij")
    assert load_rig(tmp_path / "transforms.json", format="nerfstudio").image_size == (640, 480)
    with pytest.raises(ValueError, match="cannot tell the rig format from the path"):
        save_rig(tmp_path / "folder", rig)
    with pytest.raises(ValueError, match="cannot write the rig format 'qualisys'"):
        save_rig(tmp_path / "rig.qca.txt", rig, format="qualisys")
    with pytest.raises(ValueError, match="the json format holds no names; leave it out"):
        save_rig(tmp_path / "named.json", rig, names=list("abcdefghij"))
    with pytest.raises(ValueError, match="the easyvis format holds no image_size or dist"):
        save_rig(
            tmp_path / "ev", rig, format="easyvis", image_size=(640, 480), dist=np.zeros((10, 5))
        )
    with pytest.raises(ValueError, match="the colmap format needs image_size="):
        save_rig(tmp_path / "colmap", rig, format="colmap")
    assert not (tmp_path / "named.json").exists() and not (tmp_path / "colmap").exists()

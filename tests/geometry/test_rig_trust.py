"""Cameras that cannot be right are refused with the view and the reason: a transposed K
(MATLAB's IntrinsicMatrix layout), a mirrored K (a focal length of the wrong sign), a rig of
float16; a view index out of range in Rig.select; points that are not (..., 3) in project."""

import jax.numpy as jnp
import numpy as np
import pytest

import cdog_jax
from cdog_jax import rig_from_arrays
from cdog_jax.synthetic import default_rig

RIG = default_rig(num_views=3)
K, R, t = (np.asarray(a, np.float64) for a in (RIG.K, RIG.R, RIG.t))


def test_a_transposed_K_is_refused_naming_the_view():
    bad = K.copy()
    bad[1] = bad[1].T
    with pytest.raises(ValueError, match=r"K of view 1 is not upper-triangular.*transposed"):
        rig_from_arrays(bad, R, t)
    with pytest.raises(ValueError, match="not upper-triangular"):  # and wherever a rig is checked
        cdog_jax.associate(
            cdog_jax.Rig(jnp.asarray(bad, jnp.float32), RIG.R, RIG.t),
            np.zeros((3, 4, 2), np.float32),
            np.zeros((3, 4), bool),
            sigma=1.0,
        )


@pytest.mark.parametrize("entry", [(0, 0), (1, 1)], ids=["fx", "fy"])
def test_a_mirrored_K_is_refused(entry):
    bad = K.copy()
    bad[2][entry] *= -1
    with pytest.raises(ValueError, match="K of view 2 has a focal length that is not positive"):
        rig_from_arrays(bad, R, t)


def test_K22_of_minus_one_is_still_a_camera():
    flipped = -K  # K / K[2, 2] is the same camera
    rig = rig_from_arrays(flipped, R, t)
    X = jnp.asarray([[0.1, 0.2, 0.3]], jnp.float32)
    np.testing.assert_allclose(
        np.asarray(cdog_jax.project(rig, X)[0]), np.asarray(cdog_jax.project(RIG, X)[0]), atol=1e-3
    )


def test_half_precision_rigs_are_refused():
    with pytest.raises(ValueError, match="dtype must be float32 or float64"):
        rig_from_arrays(K, R, t, dtype=jnp.float16)
    rig = rig_from_arrays(K.round().astype(np.int64), R, t)  # integers are converted
    assert rig.K.dtype == jnp.float32
    # Arrays already rounded to float16 are refused, whatever dtype is asked for.
    with pytest.raises(ValueError, match="t has dtype float16, too coarse for a camera"):
        rig_from_arrays(K, R, t.astype(np.float16))
    with pytest.raises(ValueError, match="K has dtype bfloat16, too coarse"):
        rig_from_arrays(jnp.asarray(K, jnp.bfloat16), R, t, dtype=jnp.float32)
    for kind in (bool, np.complex64):
        with pytest.raises(
            ValueError, match=f"R must hold real numbers; got dtype {np.dtype(kind)}"
        ):
            rig_from_arrays(K, R.astype(kind), t)


def test_select_refuses_an_index_out_of_range():
    assert RIG.select([2, 0]).num_views == 2 and RIG.select([-1]).num_views == 1
    with pytest.raises(ValueError, match="view index 3 is out of range for a rig of 3 views"):
        RIG.select([0, 3])
    with pytest.raises(ValueError, match="view index -4"):
        RIG.select(np.array([-4]))
    with pytest.raises(ValueError, match="must be integers"):
        RIG.select([0.0, 1.0])


def test_project_refuses_points_that_are_not_3d():
    # The function itself, without the shape checker this test run wraps around it.
    project = getattr(cdog_jax.project, "__wrapped__", cdog_jax.project)
    with pytest.raises(ValueError, match=r"X_world must have shape \(..., 3\)"):
        project(RIG, jnp.zeros((5, 2)))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        project(RIG, jnp.zeros(()))


def _far(offset):
    """The rig's world moved by ``offset``: ``t`` of X_cam = R (X - offset) + t, float64
    (R made orthonormal in float64 first: float32's 1e-7 would move a centre 1e6 out by 0.1)."""
    return t - np.einsum("mij,j->mi", _orthonormal(R), offset)


def _orthonormal(R):
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def test_a_rig_far_from_its_world_origin_is_refused_or_centred():
    """UTM-like coordinates: float32 rounds a camera 1e6 units out by 0.06 units, pixels of
    epipolar distance. rig_from_arrays refuses, naming the origin to give; given it, the rig
    is the one near its origin and so is every association, its points less the origin."""
    import jax

    offset = np.array([1e6, 5e5, 10.0])
    with pytest.raises(
        ValueError,
        match=r"1e\+06 units from the world origin.*centre: origin=\(99999\d\.\d{6}, 49999\d\.\d{6}, 12\.\d{6}\)",
    ):
        rig_from_arrays(K, _orthonormal(R), _far(offset))
    with pytest.raises(ValueError, match="origin must be 3 finite numbers"):
        rig_from_arrays(K, R, t, origin=[1.0, np.nan, 0.0])
    near = rig_from_arrays(K, _orthonormal(R), _far(offset), origin=offset)
    np.testing.assert_allclose(np.asarray(near.t), np.asarray(RIG.t), atol=1e-6)
    # a rig in millimetres rounds as one in metres; 100 units out is still held
    rig_from_arrays(K, R, 1000.0 * t)
    rig_from_arrays(K, R, _far(np.array([100.0, 0.0, 0.0])))
    scene = cdog_jax.synthetic.generate_scene(jax.random.PRNGKey(3), RIG, 20, 0.5, capacity=20)
    want = cdog_jax.associate(RIG, scene.xy, scene.mask, sigma=0.5)
    got = cdog_jax.associate(near, scene.xy, scene.mask, sigma=0.5)
    np.testing.assert_array_equal(np.asarray(got.labels), np.asarray(want.labels))
    n = int(want.num_groups)
    assert n > 10
    np.testing.assert_allclose(
        np.asarray(got.points3d)[:n], np.asarray(want.points3d)[:n], atol=1e-5
    )


def test_rig_files_take_an_origin():
    """load_rig's origin: refused without one (naming origin='cameras'), centred with
    'cameras' or 'auto', and 'auto' leaves a rig near its origin as it is."""
    import json
    import tempfile

    from cdog_jax.io import load_rig

    offset = np.array([3e5, -2e6, 50.0])
    with tempfile.TemporaryDirectory() as folder:
        path = f"{folder}/far.json"
        views = [
            {"K": K[m].tolist(), "R": _orthonormal(R)[m].tolist(), "t": _far(offset)[m].tolist()}
            for m in range(3)
        ]
        with open(path, "w") as f:
            json.dump({"views": views}, f)
        with pytest.raises(ValueError, match=r"far\.json: the cameras lie .* origin='cameras'"):
            load_rig(path)
        centres = -np.einsum("mji,mj->mi", _orthonormal(R), t)
        for origin in ("cameras", "auto"):
            rig_file = load_rig(path, origin=origin)
            np.testing.assert_allclose(rig_file.origin, offset + centres.mean(axis=0), atol=1e-6)
            np.testing.assert_allclose(
                rig_file.rig.centers_and_dirs_on_host()[0],
                centres - centres.mean(axis=0),
                atol=1e-5,
            )
        near = f"{folder}/near.json"
        views = [{"K": K[m].tolist(), "R": R[m].tolist(), "t": t[m].tolist()} for m in range(3)]
        with open(near, "w") as f:
            json.dump({"views": views}, f)
        assert load_rig(near, origin="auto").origin is None
        with pytest.raises(ValueError, match="origin must be 'cameras', 'auto' or 3 numbers"):
            load_rig(near, origin="centre")


def test_a_stereo_pair_is_judged_at_the_depth_its_axes_meet():
    """A stereo pair of 10 cm converging 20 m ahead, 1 km from its world's origin: float32
    moves its epipolar lines there by about 1000 px · 6e-5 m / 20 m (held); 1e5 km out, by
    pixels (refused). Judged at the cameras' spread instead (5 cm), the first would be
    refused too."""
    from cdog_jax.geometry._camera import ROUNDING_PX_LIMIT, rounding_px

    def pair(offset):
        o = np.array([offset, 0.0, 0.0])
        Rs, ts = [], []
        for y in (-0.05, 0.05):
            c, target = o + [0.0, y, 1.5], o + [20.0, 0.0, 1.5]
            z = (target - c) / np.linalg.norm(target - c)
            x = np.cross([0.0, 0.0, 1.0], z)
            x /= np.linalg.norm(x)
            Rm = np.stack([x, np.cross(z, x), z])
            Rs.append(Rm)
            ts.append(-Rm @ c)
        return np.stack([np.diag([1000.0, 1000.0, 1.0])] * 2), np.stack(Rs), np.stack(ts)

    held = rounding_px(*pair(1e3), np.float32)
    assert 1e-3 < held < ROUNDING_PX_LIMIT
    rig_from_arrays(*pair(1e3))
    with pytest.raises(ValueError, match="units from the world origin"):
        rig_from_arrays(*pair(1e8))

"""Numbers that cannot be right are refused before any work, with a message that names the
argument, the value and where (scene, field). Only the few tests that check an accepted
input compile anything.

The tests run with jaxtyping+beartype on every annotated function, which would refuse some
of these arguments first; ``plain(f)`` is ``f`` without that wrapper, as users call it."""

import inspect
import math
import re

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_scene, ring_rig

import cdog_jax
from cdog_jax import Config, Rig, associate, associate_batch, triangulate

plain = inspect.unwrap


def plain_config(**fields):
    """``Config(**fields)`` without the test-time type checker on ``__init__``."""
    config = Config.__new__(Config)
    plain(Config.__init__)(config, **fields)
    return config


@pytest.fixture(scope="module")
def scene():
    rig = ring_rig(3)
    xy, mask, _, _ = random_scene(rig, 4, 6)
    return rig, xy.astype(np.float32), mask


@pytest.fixture(scope="module")
def batch(scene):
    rig, xy, mask = scene
    return rig, np.stack([xy, xy]), np.stack([mask, mask])


# --- xy dtypes ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "dtype, message",
    [
        (np.float16, "float16, too coarse.*use float32 or float64"),
        (jnp.bfloat16, "bfloat16, too coarse.*use float32 or float64"),
        (np.complex64, "real pixel coordinates.*complex64"),
        (np.bool_, "real pixel coordinates.*bool"),
    ],
)
def test_xy_dtypes_that_cannot_hold_pixels_are_refused(scene, dtype, message):
    rig, xy, mask = scene
    with pytest.raises(ValueError, match=message):
        associate(rig, np.asarray(xy).astype(dtype), mask)
    with pytest.raises(ValueError, match=message):
        associate_batch(rig, np.stack([xy, xy]).astype(dtype), np.stack([mask, mask]))


def test_integer_xy_is_converted_to_float(scene):
    rig, xy, mask = scene
    xy_int = np.round(xy).astype(np.int32)
    got = associate(rig, xy_int, mask)
    want = associate(rig, xy_int.astype(np.float32), mask)
    np.testing.assert_array_equal(got.labels, want.labels)
    assert got.points3d.dtype == jnp.float32


# --- sigma ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "sigma, error, message",
    [
        (None, TypeError, "sigma must be a number.*got NoneType None"),
        (math.nan, ValueError, "sigma must be a finite number >= 0 .*got nan"),
        (-1.0, ValueError, "sigma must be a finite number >= 0 .*got -1.0"),
        (math.inf, ValueError, "sigma must be a finite number >= 0 .*got inf"),
        (
            1e39,
            ValueError,
            r"sigma = 1e\+39 px is larger than the image diagonal 8\d\d\.\d px \(twice the largest principal point of rig.K\)",
        ),
        ("1.0", ValueError, "sigma must be a number .*\"auto\".*got '1.0'"),
        (np.ones(3), ValueError, r"sigma must be a scalar for one scene; got shape \(3,\)"),
    ],
)
def test_impossible_sigma_is_refused(scene, sigma, error, message):
    rig, xy, mask = scene
    with pytest.raises(error, match=message):
        plain(associate)(rig, xy, mask, sigma=sigma)


def test_sigma_bound_is_the_detections_extent_when_larger(scene):
    rig, xy, mask = scene
    far = np.where(mask[..., None], xy * 10.0, 0.0).astype(np.float32)  # beyond the image
    extent = math.hypot(*np.abs(far[mask]).max(axis=0))
    with pytest.raises(ValueError, match=f"the detections' extent {extent:.1f} px"):
        associate(rig, far, mask, sigma=extent * 1.01)


@pytest.mark.parametrize(
    "sigma, message",
    [
        (
            np.ones(3),
            r"sigma must be a scalar or have shape \(B,\) = \(2,\), one per scene; got shape \(3,\)",
        ),
        (np.array([1.0, np.nan]), "sigma of scene 1 must be a finite number >= 0 .*got nan"),
        (np.array([-2.0, 1.0]), "sigma of scene 0 must be a finite number >= 0 .*got -2.0"),
        (np.array([1.0, 1e39]), r"sigma of scene 1 = 1e\+39 px is larger than the image diagonal"),
        (None, "sigma must be a number .*a \\(B,\\) array"),
    ],
)
def test_impossible_batch_sigma_names_the_scene(batch, sigma, message):
    rig, xy, mask = batch
    with pytest.raises((ValueError, TypeError), match=message):
        plain(associate_batch)(rig, xy, mask, sigma=sigma)


# --- Config and thresholds -----------------------------------------------------------------


@pytest.mark.parametrize(
    "changes, message",
    [
        (dict(delta=0.0), r"Config.delta must be finite and in \(0, 1\]; got 0.0"),
        (dict(delta=1.5), r"Config.delta must be finite and in \(0, 1\]; got 1.5"),
        (dict(alpha_tau=-1.0), r"Config.alpha_tau must be finite and in \[0, inf\); got -1.0"),
        (dict(tau_min_px=-0.5), "Config.tau_min_px must be .*got -0.5"),
        (dict(iqr_alpha=math.nan), "Config.iqr_alpha must be finite .*got nan"),
        (dict(jump_kappa=math.inf), "Config.jump_kappa must be finite .*got inf"),
        (dict(support_alpha=2.0), r"Config.support_alpha must be finite and in \[0, 1\]; got 2.0"),
    ],
)
def test_config_numbers_out_of_range_are_refused_when_made_or_replaced(changes, message):
    with pytest.raises(ValueError, match=message):
        Config(**changes)
    with pytest.raises(ValueError, match=message):
        Config.reference().replace(**changes)


def test_config_field_types_are_checked():
    with pytest.raises(TypeError, match="Config.delta must be a real number; got str '0.5'"):
        plain_config(delta="0.5")
    with pytest.raises(TypeError, match="Config.iqr must be True or False; got 1"):
        plain_config(iqr=1)
    with pytest.raises(ValueError, match="Config.max_iqr_iters must be a positive int; got True"):
        plain_config(max_iqr_iters=True)


def test_every_numeric_field_has_a_range():
    from cdog_jax.cdog._pipeline import RANGES

    assert set(Config().thresholds()._fields) == set(RANGES)


def test_thresholds_out_of_range_are_refused(scene, batch):
    rig, xy, mask = scene
    thresholds = Config().thresholds(1.0)
    with pytest.raises(
        ValueError, match=r"thresholds.delta must be finite and in \(0, 1\]; got nan"
    ):
        associate(rig, xy, mask, thresholds=thresholds._replace(delta=np.float32(np.nan)))
    with pytest.raises(ValueError, match=r"thresholds.iqr_alpha must be .*got -1.0"):
        associate(rig, xy, mask, thresholds=thresholds._replace(iqr_alpha=np.float32(-1.0)))
    with pytest.raises(ValueError, match=r"thresholds.delta must be a scalar; got shape \(2,\)"):
        associate(
            rig, xy, mask, thresholds=thresholds._replace(delta=np.array([0.5, 0.6], np.float32))
        )
    rig, xy_b, mask_b = batch
    with pytest.raises(
        ValueError,
        match=r"thresholds.delta must be finite and in \(0, 1\]; got 2.0 at index \(1,\)",
    ):
        associate_batch(
            rig,
            xy_b,
            mask_b,
            thresholds=thresholds._replace(delta=np.array([0.5, 2.0], np.float32)),
        )
    with pytest.raises(
        ValueError,
        match=r"thresholds.delta must be a scalar or shape \(B,\) = \(2,\); got shape \(3,\)",
    ):
        associate_batch(
            rig, xy_b, mask_b, thresholds=thresholds._replace(delta=np.full(3, 0.5, np.float32))
        )


# --- methods by name ------------------------------------------------------------------------


def test_method_by_registered_name(scene):
    rig, xy, mask = scene
    by_name = associate(rig, xy, mask, method="paper")
    np.testing.assert_array_equal(
        by_name.labels, associate(rig, xy, mask, method=Config.paper()).labels
    )
    with pytest.raises(
        ValueError,
        match=r"associate: unknown method 'papr'; registered: best, extended, paper, reference",
    ):
        associate(rig, xy, mask, method="papr")
    with pytest.raises(
        TypeError, match="associate_batch: method must be a Method or a registered name .*got int"
    ):
        plain(associate_batch)(rig, xy[None], mask[None], method=3)
    with pytest.raises(
        TypeError, match="unexpected keyword argument 'config'"
    ):  # the name before 0.1
        associate(rig, xy, mask, config="paper")


# --- associate_batch: lists, per-scene rigs -------------------------------------------------


def test_batch_accepts_lists_like_associate(batch):
    rig, xy, mask = batch
    from_lists = associate_batch(rig, xy.tolist(), mask.tolist())
    from_arrays = associate_batch(rig, xy, mask)
    np.testing.assert_array_equal(from_lists.labels, from_arrays.labels)


def test_per_scene_rig_with_another_B_is_refused(batch):
    rig, xy, mask = batch
    rig3 = Rig(*(jnp.stack([a] * 3) for a in (rig.K, rig.R, rig.t)))
    with pytest.raises(
        ValueError,
        match=r"the per-scene rig has 3 scenes \(rig.K shape \(3, 3, 3, 3\)\) but xy has B=2",
    ):
        associate_batch(rig3, xy, mask)


# --- triangulate ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "views_xy, views_mask, weights_shape, message",
    [
        (
            2,
            2,
            None,
            r"triangulate: xy must have shape \(M, \*S, 2\), the view axis first, with M=3 views from the rig; got \(2, 6, 2\)",
        ),
        (
            3,
            2,
            None,
            r"triangulate: mask must have shape \(3, 6\) \(one flag per view of each track\); got \(2, 6\)",
        ),
        (3, 3, (2, 6), r"triangulate: weights must have the shape of mask \(3, 6\); got \(2, 6\)"),
    ],
)
def test_triangulate_view_mismatch_is_a_plain_message(
    scene, views_xy, views_mask, weights_shape, message
):
    rig, xy, mask = scene
    tracks_xy = xy[:views_xy]  # (M, P, 2)
    tracks_mask = mask[:views_mask]
    weights = None if weights_shape is None else np.ones(weights_shape, np.float32)
    with pytest.raises(ValueError, match=message):
        plain(triangulate)(rig, jnp.asarray(tracks_xy), jnp.asarray(tracks_mask), weights=weights)


def test_triangulate_refuses_a_batched_rig(scene):
    rig, xy, mask = scene
    rig2 = Rig(*(jnp.stack([a] * 2) for a in (rig.K, rig.R, rig.t)))
    with pytest.raises(
        ValueError,
        match=r"triangulate: rig.K must have shape \(M, 3, 3\) \(one rig; vmap over many\); got \(2, 3, 3, 3\)",
    ):
        plain(cdog_jax.geometry.triangulate)(rig2, jnp.asarray(xy), jnp.asarray(mask))


# --- argument types of public functions ------------------------------------------------------

import cdog_jax.benchmark  # noqa: E402
import cdog_jax.calibration  # noqa: E402
import cdog_jax.io  # noqa: E402
import cdog_jax.metrics  # noqa: E402
import cdog_jax.refine  # noqa: E402
import cdog_jax.synthetic  # noqa: E402

_RIG = ring_rig(3)
_XY = jnp.zeros((3, 4, 2), jnp.float32)
_MASK = jnp.ones((3, 4), bool)
_PATH_MSG = "a path (str or os.PathLike)"
_ARRAY_MSG = r"an array \(jax.Array, numpy.ndarray, list or number\)"
_TH = Config().thresholds(1.0)

# (function, arguments, keyword arguments, the expected message)
WRONG_TYPES = [
    (
        cdog_jax.associate,
        (_XY, _RIG, _MASK),
        {},
        "associate: rig must be Rig; got ArrayImpl of shape (3, 4, 2)",
    ),
    (
        cdog_jax.associate,
        (_RIG, _XY, _MASK),
        {"thresholds": Config()},
        "associate: thresholds must be Thresholds or None; got Config",
    ),
    (
        cdog_jax.associate_batch,
        (_XY, _RIG, _MASK),
        {},
        "associate_batch: rig must be Rig; got ArrayImpl",
    ),
    (
        cdog_jax.associate_batch,
        (_RIG, _XY[None], _MASK[None]),
        {"batch_size": 2.5},
        "associate_batch: batch_size must be an int; got float 2.5",
    ),
    (
        cdog_jax.associate_traced,
        (_RIG, _XY, _MASK, Config(), _TH),
        {},
        "associate_traced: thresholds must be Thresholds; got Config",
    ),
    (cdog_jax.triangulate, (_XY, _RIG, _MASK), {}, "triangulate: rig must be Rig; got ArrayImpl"),
    (cdog_jax.project, ("points.npy", _RIG), {}, "project: rig must be Rig; got str 'points.npy'"),
    (cdog_jax.project, (_RIG, _RIG), {}, f"project: X_world must be {_ARRAY_MSG}; got Rig"),
    (cdog_jax.plot_rig, ("rig.json",), {}, "plot_rig: rig must be Rig; got str 'rig.json'"),
    (
        cdog_jax.rig_from_arrays,
        (_RIG.K, _RIG.R, None),
        {},
        f"rig_from_arrays: t must be {_ARRAY_MSG}; got None",
    ),
    (cdog_jax.geometry.describe_rig, ("rig.json",), {}, "describe_rig: rig must be Rig; got str"),
    (
        cdog_jax.geometry.fundamental_from_rig,
        (_RIG.K,),
        {},
        "fundamental_from_rig: rig must be Rig; got ArrayImpl",
    ),
    (
        cdog_jax.geometry.epipolar_distances,
        (_RIG, _MASK, "xy"),
        {},
        f"epipolar_distances: mask must be {_ARRAY_MSG}; got str 'xy'",
    ),
    (
        cdog_jax.geometry.undistort_pixels,
        (_RIG.K, jnp.zeros((3, 5)), _XY),
        {"iterations": 2.0},
        "undistort_pixels: iterations must be an int; got float 2.0",
    ),
    (
        cdog_jax.geometry.params_from_rig,
        (_RIG.K,),
        {},
        "params_from_rig: rig must be Rig; got ArrayImpl",
    ),
    (
        cdog_jax.geometry.rig_from_params,
        (_RIG,),
        {},
        "rig_from_params: params must be CameraParams; got Rig",
    ),
    (
        cdog_jax.io.save_rig,
        (_RIG, "rig.json"),
        {},
        f"save_rig: path must be {_PATH_MSG}; got Rig",
    ),
    (
        cdog_jax.io.save_rig,
        ("rig.npz", "rig.json"),
        {},
        "save_rig: rig must be Rig; got str 'rig.json'",
    ),
    (
        cdog_jax.io.save_rig,
        (_RIG, "folder"),
        {"format": "colmap", "image_size": (640, 480)},
        f"save_rig: path must be {_PATH_MSG}; got Rig",
    ),
    (cdog_jax.io.load_rig, (_RIG,), {}, f"load_rig: path must be {_PATH_MSG}; got Rig"),
    (
        cdog_jax.io.load_detections,
        (None,),
        {},
        f"load_detections: path must be {_PATH_MSG}; got None",
    ),
    (
        cdog_jax.io.detections_from_lists,
        ("view0",),
        {},
        "detections_from_lists: views must be list or tuple; got str 'view0'",
    ),
    (
        cdog_jax.io.save_association_json,
        (_RIG, "out.json", _XY, _MASK),
        {},
        f"save_association_json: path must be {_PATH_MSG}; got Rig",
    ),
    (
        cdog_jax.io.save_association_csv,
        ("out.csv", _XY),
        {},
        "save_association_csv: assoc must be an Association (or an object with its fields); got ArrayImpl",
    ),
    (
        cdog_jax.io.save_association_npz,
        ("out.npz", "result"),
        {},
        "save_association_npz: assoc must be an Association (or an object with its fields); got str 'result'",
    ),
    (
        cdog_jax.io.load_association_json,
        (3,),
        {},
        f"load_association_json: path must be {_PATH_MSG}; got int 3",
    ),
    (
        cdog_jax.io._association_files.association_records,
        (_XY, _XY, _MASK),
        {},
        "association_records: assoc must be an Association (or an object with its fields); got ArrayImpl",
    ),
    (
        cdog_jax.synthetic.default_rig,
        (),
        {"num_views": 2.0},
        "default_rig: num_views must be an int; got float 2.0",
    ),
    (
        cdog_jax.synthetic._rig.negate_intrinsics,
        ([0], _RIG),
        {},
        "negate_intrinsics: rig must be Rig; got list",
    ),
    (
        cdog_jax.synthetic.generate_scene,
        (_RIG, jnp.zeros(2, jnp.uint32), 5, 1.0),
        {"capacity": 8},
        f"generate_scene: key must be {_ARRAY_MSG}; got Rig",
    ),
    (
        cdog_jax.synthetic.visible_box,
        ((640, 480), _RIG),
        {},
        "visible_box: rig must be Rig; got tuple",
    ),
    (
        cdog_jax.metrics.scene_metrics,
        (_RIG, _XY, _XY),
        {},
        "scene_metrics: result must be Association; got ArrayImpl",
    ),
    (cdog_jax.metrics.mean_metrics, ({},), {}, "mean_metrics: metrics must be Metrics; got dict"),
    (cdog_jax.benchmark.sweep, ("grid", _RIG), {}, "sweep: rig must be Rig; got str 'grid'"),
    (
        cdog_jax.benchmark.save_results,
        ("out", "result"),
        {},
        "save_results: result must be SweepResult; got str 'out'",
    ),
    (
        cdog_jax.benchmark.load_results,
        (None,),
        {},
        f"load_results: directory must be {_PATH_MSG}; got None",
    ),
    (
        cdog_jax.benchmark.summary_table,
        ("results",),
        {},
        "summary_table: result must be SweepResult; got str",
    ),
    (
        cdog_jax.calibration.rig_errors,
        (_RIG, _RIG.K),
        {},
        "rig_errors: reference must be Rig; got ArrayImpl",
    ),
    (
        cdog_jax.calibration.align_rigs,
        ("rig.json", _RIG),
        {},
        "align_rigs: rig must be Rig; got str",
    ),
    (
        cdog_jax.calibration.calibrate,
        (_RIG, _XY[None], _MASK[None]),
        {"thresholds": Config(), "method": _TH},
        r"calibrate: method must be a Method or a registered name \(.*\); got Thresholds",
    ),
    (
        cdog_jax.calibration.calibrate,
        (_RIG, _XY[None], _MASK[None]),
        {"thresholds": Config(), "method": "paper"},
        "calibrate: thresholds must be Thresholds (method.thresholds()); got Config",
    ),
    (
        cdog_jax.calibration.bpe,
        (_XY, _RIG, jnp.zeros((2, 3), jnp.int32), jnp.ones(2, bool)),
        {},
        "bpe: rig must be Rig; got ArrayImpl",
    ),
]


@pytest.mark.parametrize(
    "fn, args, kwargs, message",
    WRONG_TYPES,
    ids=[f"{c[0].__name__}-{i}" for i, c in enumerate(WRONG_TYPES)],
)
def test_public_functions_name_the_expected_and_received_types(fn, args, kwargs, message):
    with pytest.raises(TypeError, match=re.escape(message) if "\\(" not in message else message):
        plain(fn)(*args, **kwargs)
    with pytest.raises(TypeError):  # the test-time type checker (where annotated) or the check
        fn(*args, **kwargs)


def test_the_rigs_focal_length_is_read_again_when_it_could_have_changed():
    """The classes' σ fit reads the rig's focal length once for the same JAX ``K`` (it
    cannot change in place) and again for a NumPy ``K`` (which can)."""
    from cdog_jax.graph._sigma import focal_scale
    from cdog_jax.people._classes import _rig_focal

    good = ring_rig(3)
    rig = Rig(jnp.asarray(good.K), jnp.asarray(good.R), jnp.asarray(good.t))
    assert _rig_focal(rig) == _rig_focal(rig) == focal_scale(np.asarray(good.K))
    K = np.array(good.K)
    on_host = Rig.__new__(Rig)
    plain(Rig.__init__)(on_host, K, np.array(good.R), np.array(good.t))
    assert _rig_focal(on_host) == focal_scale(K)
    K *= 2.0  # in place
    assert _rig_focal(on_host) == focal_scale(K) == 2.0 * focal_scale(np.asarray(good.K))


def test_a_rig_checked_once_is_checked_again_when_it_could_have_changed():
    """The rig's value checks are skipped for the same JAX arrays as the last rig checked
    (they cannot change in place), and run again for NumPy arrays (which can) and for a
    batched use of the same arrays."""
    from cdog_jax._validate import check_rig

    good = ring_rig(3)
    rig = Rig(jnp.asarray(good.K), jnp.asarray(good.R), jnp.asarray(good.t))
    check_rig(rig)
    check_rig(rig)  # the same arrays: nothing to read again
    K = np.array(good.K)
    on_host = Rig.__new__(Rig)  # NumPy arrays, as a caller without the type checker gives
    plain(Rig.__init__)(on_host, K, np.array(good.R), np.array(good.t))
    check_rig(on_host)
    K[1] = 0.0  # in place, after a check
    with pytest.raises(ValueError, match="K of view 1 is singular"):
        check_rig(on_host)
    with pytest.raises(ValueError, match=r"rig.K must have shape \(B, M, 3, 3\)"):
        check_rig(rig, batched=True)  # the same arrays, another question
    bad_R = np.array(good.R)
    bad_R[2] *= 1.1
    bad = Rig(rig.K, jnp.asarray(bad_R), rig.t)
    for _ in range(2):
        with pytest.raises(ValueError, match="R of view 2 is not a rotation"):
            check_rig(bad)

"""plot_rig: a headless 3D picture of the cameras, frusta at the camera centres."""

import matplotlib
import numpy as np
import pytest

from cdog_jax.synthetic import IMAGE_SIZE, default_rig
from cdog_jax.synthetic._rig import negate_intrinsics
from cdog_jax.viz import plot_rig


def test_default_rig_to_png(tmp_path):
    rig = negate_intrinsics(default_rig(), [1])  # one OpenMVG-style K[2,2] = -1
    points = np.random.default_rng(0).uniform([-1, -0.75, 0], [1, 0.75, 0.5], size=(20, 3))
    backend = matplotlib.get_backend()
    ax = plot_rig(rig, points=points, image_size=IMAGE_SIZE, names=[f"cam{m}" for m in range(10)])
    path = tmp_path / "rig.png"
    ax.figure.savefig(path)
    assert path.stat().st_size > 10_000
    assert matplotlib.get_backend() == backend  # pyplot's state untouched

    centers = np.asarray(rig.centers, np.float64)
    R = np.asarray(rig.R, np.float64)
    frusta = [np.stack(line.get_data_3d(), axis=-1) for line in ax.lines[: len(centers)]]
    for m, path_m in enumerate(frusta):
        # Each frustum starts at its camera centre, and its corners lie in front of it.
        np.testing.assert_allclose(path_m[0], centers[m], atol=1e-5)
        depth = (path_m[1:5] - centers[m]) @ R[m, 2]
        assert np.all(depth > 0), depth
        np.testing.assert_allclose(depth, depth[0], rtol=1e-5)
    assert "scene units" in ax.get_xlabel() and "scene units" in ax.get_zlabel()
    assert {t.get_text().strip() for t in ax.texts} >= {f"cam{m}" for m in range(10)}
    lims = np.array([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()])
    spans = np.diff(lims, axis=1).ravel()
    np.testing.assert_allclose(spans, spans[0])  # equal aspect


def test_draws_into_given_axes_and_without_image_size():
    from matplotlib.figure import Figure

    ax = Figure().add_subplot(projection="3d")
    out = plot_rig(default_rig(num_views=3), ax=ax, frustum_depth=0.2)
    assert out is ax and len(ax.lines) >= 3
    with pytest.raises(ValueError, match="names must hold M=3"):
        plot_rig(default_rig(num_views=3), names=["a"])

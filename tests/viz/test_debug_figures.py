"""The figures to debug an association with: the association itself (groups followable
across views, wrong groups marked), the epipolar lines of one detection, the BPE histogram
and the rays through the detections. Each renders headless, saves, has a sane size, and
draws what it says."""

import jax
import matplotlib.image
import numpy as np
import pytest

import cdog_jax
from cdog_jax import plot_association, plot_bpe_histogram, plot_epipolar, plot_rays
from cdog_jax.synthetic import default_rig, generate_scene
from cdog_jax.viz._plot import group_style, wrong_groups


@pytest.fixture(scope="module")
def tiny():
    """The 12-point scene of the demo test (same shapes: the compiled pipeline is reused)."""
    rig = default_rig()
    scene = generate_scene(jax.random.PRNGKey(3), rig, 12, 1.0, capacity=12)
    return rig, scene, cdog_jax.associate(rig, scene.xy, scene.mask, sigma=1.0)


def _png_size(path):
    height, width = matplotlib.image.imread(path).shape[:2]
    return width, height


def test_group_styles_do_not_repeat():
    styles = {(tuple(np.round(group_style(g)[0], 3)), group_style(g)[1]) for g in range(300)}
    assert len(styles) == 300


def test_wrong_groups_hand_built():
    instance = np.array([[0, 1, -1], [1, 0, 2]])  # (M=2, P=3)
    groups = np.array([[0, 1], [1, 0], [2, 2], [0, -1]])  # right, right, clutter, one member
    valid = np.array([True, True, True, False])
    np.testing.assert_array_equal(
        wrong_groups(groups, valid, instance), [False, False, True, False]
    )
    np.testing.assert_array_equal(
        wrong_groups(np.array([[0, 0]]), np.array([True]), instance), [True]
    )


def test_association_figure_marks_wrong_groups_and_is_legible(tmp_path, tiny):
    rig, scene, result = tiny
    instance = np.asarray(scene.instance).copy()
    g = int(np.flatnonzero(np.asarray(result.valid))[0])
    m, slot = [(m, s) for m, s in enumerate(np.asarray(result.groups)[g]) if s >= 0][0]
    instance[m, slot] = 999  # make one group wrong
    path = tmp_path / "assoc.png"
    fig = plot_association(rig, scene.xy, scene.mask, result, instance=instance, path=path)
    n_wrong = int(wrong_groups(result.groups, result.valid, instance).sum())
    assert n_wrong >= 1 and f"{n_wrong} wrong" in fig.get_suptitle()
    width, height = _png_size(path)
    assert 1000 <= width <= 1800 and 800 <= height <= 1400, (width, height)
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("wrong group" in s for s in legend)
    # Every assigned detection carries its group's number.
    numbers = [t.get_text() for t in fig.axes[m].texts]
    assert str(int(np.asarray(result.labels)[m, slot])) in numbers


def test_epipolar_figure(tmp_path, tiny):
    rig, scene, result = tiny
    mask = np.asarray(scene.mask)
    view = 0
    slot = int(np.flatnonzero(mask[view])[0])
    path = tmp_path / "epi.png"
    fig = plot_epipolar(
        rig, scene.xy, scene.mask, view, slot, result=result, instance=scene.instance, path=path
    )
    width, height = _png_size(path)
    assert 1000 <= width <= 1800 and 400 <= height <= 1000, (width, height)
    assert len(fig.axes) == rig.num_views
    # The line drawn in view n passes within a few px of the true partner (σ = 1 px).
    instance = np.asarray(scene.instance)
    xy = np.asarray(scene.xy, np.float64)
    checked = 0
    for n in range(rig.num_views):
        partner = np.flatnonzero(mask[n] & (instance[n] == instance[view, slot]))
        if n == view or partner.size == 0:
            continue
        line = [ln for ln in fig.axes[n].get_lines() if len(ln.get_xdata()) == 2][0]
        p0, p1 = np.array(line.get_xydata())
        d = p1 - p0
        offset = xy[n, partner[0]] - p0
        assert abs(d[0] * offset[1] - d[1] * offset[0]) / np.linalg.norm(d) < 6.0
        checked += 1
    assert checked >= 1
    assert "τ = " in fig.get_suptitle()
    with pytest.raises(ValueError, match="is not a detection"):
        plot_epipolar(
            rig,
            scene.xy,
            scene.mask,
            view,
            int(np.flatnonzero(~mask[view])[0]) if (~mask[view]).any() else 99,
            tau_px=3.0,
        )
    with pytest.raises(ValueError, match="give tau_px or result"):
        plot_epipolar(rig, scene.xy, scene.mask, view, slot)


def test_bpe_histogram(tmp_path, tiny):
    _, _, result = tiny
    path = tmp_path / "bpe.png"
    fig = plot_bpe_histogram(result, path=path)
    (ax,) = fig.axes
    heights = sum(p.get_height() for p in ax.patches)
    valid = np.asarray(result.valid)
    assert heights == valid.sum() > 0
    median = np.median(np.asarray(result.bpe)[valid])
    assert any(np.isclose(ln.get_xdata()[0], median) for ln in ax.get_lines())
    assert 600 <= _png_size(path)[0] <= 1200
    batched = jax.tree_util.tree_map(lambda a: np.stack([a, a]), result)
    fig = plot_bpe_histogram(batched)
    assert sum(p.get_height() for p in fig.axes[0].patches) == 2 * valid.sum()
    assert "over 2 frames" in fig.axes[0].get_title(loc="left")


def test_rays_meet_at_the_group_points(tmp_path, tiny):
    rig, scene, result = tiny
    mask = np.asarray(scene.mask)
    ax = plot_rays(rig, scene.xy, scene.mask, result=result)
    ax.figure.savefig(tmp_path / "rays.png")
    rays = ax.lines[-int(mask.sum()) :]
    centers = np.asarray(rig.centers, np.float64)
    labels = np.asarray(result.labels)
    points = np.asarray(result.points3d, np.float64)
    for ray, (m, p) in zip(rays, zip(*np.nonzero(mask))):
        start, end = np.stack(ray.get_data_3d(), axis=-1)
        np.testing.assert_allclose(start, centers[m], atol=1e-5)
        g = labels[m, p]
        if g >= 0 and np.asarray(result.valid)[g]:
            d = (end - start) / np.linalg.norm(end - start)
            miss = np.linalg.norm(np.cross(points[g] - start, d))
            assert miss < 0.05, (m, p, miss)  # scene units; σ = 1 px at ~3 units

"""Benchmark figures on fake sweep results: every figure draws and saves, averages follow docs/BENCHMARK.md §2."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax.metrics import Metrics
from cdog_jax.viz import heatmaps, metrics_vs_sigma, surfaces, time_vs_count, views_ablation
from cdog_jax.viz._benchmark_common import cell_means, scenes_for

PNG = b"\x89PNG\r\n\x1a\n"
FIELDS = tuple(f.name for f in dataclasses.fields(Metrics))


def _grid(seed=0, sigmas=(0.0, 1.0, 3.0, 5.0), counts=(1, 5, 20, 40, 130), scenes=2):
    """Fake sweep: per-scene sigma, count, and random metrics/times for two methods."""
    rng = np.random.default_rng(seed)
    s, c, _ = np.meshgrid(
        np.asarray(sigmas, np.float32), np.asarray(counts), np.arange(scenes), indexing="ij"
    )
    sigma, count = s.ravel(), c.ravel()
    S = sigma.size

    def method():
        m = {f: rng.uniform(0.0, 1.0, S) for f in FIELDS}
        m["num_err_groups"] = rng.integers(0, 3, S)
        m["err3d"] = np.where(m["num_err_groups"] > 0, rng.uniform(0.0, 1.0, S), 0.0)
        m["bpe_px"] = np.where(m["num_err_groups"] > 0, rng.uniform(0.0, 10.0, S), 0.0)
        return m

    metrics = {"paper()": method(), "reference()": method()}
    time_s = {k: rng.lognormal(-5.0, 0.3, S) * (1 + count / 50) for k in metrics}
    return sigma, count, metrics, time_s


def _as_metrics(m):
    """A batched Metrics (as ``jax.vmap(scene_metrics, ...)`` returns) from a dict of fields."""
    ints = ("num_pred_groups", "num_gt_groups", "num_unassigned", "num_err_groups")
    leaves = {
        f: jnp.asarray(m[f], jnp.int32 if f in ints else bool if f == "has_groups" else jnp.float32)
        for f in FIELDS
    }
    return jax.vmap(lambda d: Metrics(**d))(leaves)


def _png_ok(path):
    assert path.is_file() and path.stat().st_size > 1000
    assert path.read_bytes()[:8] == PNG


def test_cell_means_exact():
    sigma = np.array([0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 2.5])
    count = np.array([5, 5, 5, 10, 10, 10, 5])
    values = np.array([0.2, 0.4, 1.0, 0.1, 0.3, 0.7, 0.9])
    sigmas, counts, table = cell_means(sigma, count, values)
    np.testing.assert_array_equal(sigmas, [0.0, 1.0, 2.5])
    np.testing.assert_array_equal(counts, [5, 10])
    expected = np.array([[0.3, 0.7], [1.0, 0.2], [0.9, np.nan]])
    np.testing.assert_allclose(table, expected, rtol=0, atol=1e-15)
    # keep drops scenes; a cell without kept scenes is NaN.
    keep = np.array([True, False, False, True, True, True, True])
    _, _, table = cell_means(sigma, count, values, keep=keep)
    np.testing.assert_allclose(
        table, [[0.2, 0.7], [np.nan, 0.2], [0.9, np.nan]], rtol=0, atol=1e-15
    )


def test_cell_means_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="count must have shape"):
        cell_means(np.zeros(4), np.zeros(3), np.zeros(4))


def test_err3d_average_skips_scenes_without_scored_groups():
    sigma = np.array([0.0, 0.0, 0.0, 1.0, 1.0])
    count = np.array([5, 5, 5, 5, 5])
    m = {
        "num_err_groups": np.array([2, 0, 1, 0, 3]),
        "err3d": np.array([0.1, 0.0, 0.3, 0.0, 0.5]),  # 0 where no group is scored (Metrics' 0/0)
        "pg_f1": np.array([1.0, 0.0, 0.5, 0.0, 1.0]),
    }
    np.testing.assert_array_equal(scenes_for(m, "err3d"), [True, False, True, False, True])
    np.testing.assert_array_equal(scenes_for(m, "pg_f1"), [True] * 5)
    _, _, table = cell_means(sigma, count, m["err3d"], keep=scenes_for(m, "err3d"))
    np.testing.assert_allclose(table[:, 0], [0.2, 0.5])
    # The curves of metrics_vs_sigma use the same rule: err3d skips, pg_f1 does not.
    fig = metrics_vs_sigma(
        sigma, {"a": m}, fields=("err3d", "pg_f1"), paper_reference=False, original_reference=False
    )
    err_ax, pg_ax = fig.axes
    np.testing.assert_allclose(err_ax.get_lines()[0].get_ydata(), [0.2, 0.5])
    np.testing.assert_allclose(pg_ax.get_lines()[0].get_ydata(), [0.5, 0.5])
    with pytest.raises(ValueError, match="num_err_groups"):
        scenes_for({"bpe_px": np.zeros(3)}, "bpe_px")


def test_heatmaps(tmp_path):
    sigma, count, metrics, _ = _grid()
    path = tmp_path / "heat.png"
    fig = heatmaps(sigma, count, metrics, method="paper()", path=path)
    assert len(fig.axes) == 3 + 1  # three panels, one shared colour bar
    _png_ok(path)
    # Cell values drawn are the cell means.
    image = fig.axes[0].get_images()[0].get_array()
    np.testing.assert_allclose(image, cell_means(sigma, count, metrics["paper()"]["pg_f1"])[2])
    # A non-score field gets its own colour bar; a batched Metrics is accepted too.
    per_method = {k: _as_metrics(v) for k, v in metrics.items()}
    fig = heatmaps(sigma, count, per_method, method="reference()", fields=("pg_f1", "err3d"))
    assert len(fig.axes) == 2 + 2
    with pytest.raises(ValueError, match="method must be one of"):
        heatmaps(sigma, count, metrics, method="nope")
    with pytest.raises(ValueError, match="lacks the fields"):
        heatmaps(sigma, count, metrics, method="paper()", fields=("pg_f2",))


def test_surfaces(tmp_path):
    sigma, count, metrics, _ = _grid()
    path = tmp_path / "surf.png"
    fig = surfaces(sigma, count, metrics, method="paper()", path=path)
    assert len(fig.axes) == 3 + 1
    assert all(ax.name == "3d" for ax in fig.axes[:3])
    _png_ok(path)


def test_time_vs_count(tmp_path):
    _, count, _, time_s = _grid()
    path = tmp_path / "time.png"
    fig = time_vs_count(count, time_s, path=path)
    (ax,) = fig.axes
    _png_ok(path)
    assert ax.get_yscale() == "log"
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("original code, full grid (docs/BENCHMARK.md §4)" in s for s in labels)
    # Median line in ms per distinct count.
    first = ax.get_lines()[0]
    np.testing.assert_array_equal(first.get_xdata(), np.unique(count))
    t_ms = np.asarray(time_s["paper()"]) * 1e3
    np.testing.assert_allclose(
        first.get_ydata(), [np.median(t_ms[count == c]) for c in np.unique(count)]
    )


def test_metrics_vs_sigma(tmp_path):
    sigma, _, metrics, _ = _grid()
    path = tmp_path / "sigma.png"
    fields = ("pg_f1", "mp_f1", "g_f1", "pg_p", "pg_r")
    fig = metrics_vs_sigma(sigma, metrics, path=path)
    assert len(fig.axes) == len(fields)
    _png_ok(path)
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert (
        "paper, full grid (docs/BENCHMARK.md §3)" in labels
        and "paper()" in labels
        and "reference()" in labels
    )
    # The paper's star markers sit at σ = 0, 1, 3, 5 with its PG-F1 values (docs/BENCHMARK.md §3).
    (star,) = [
        ln
        for ln in fig.axes[0].get_lines()
        if ln.get_label() == "paper, full grid (docs/BENCHMARK.md §3)"
    ]
    np.testing.assert_allclose(star.get_xdata(), [0, 1, 3, 5])
    np.testing.assert_allclose(star.get_ydata(), [0.937, 0.880, 0.761, 0.636])
    fig = metrics_vs_sigma(
        sigma, metrics, fields=("err3d", "bpe_px", "num_unassigned"), paper_reference=False
    )
    assert len(fig.axes) == 3


def test_views_ablation(tmp_path):
    rng = np.random.default_rng(1)
    views = np.repeat(np.arange(2, 11), 2)
    values = {"paper()": rng.uniform(size=views.size), "reference()": rng.uniform(size=views.size)}
    path = tmp_path / "views.png"
    fig = views_ablation(views, values, path=path)
    (ax,) = fig.axes
    _png_ok(path)
    ours, _, paper = ax.get_lines()
    np.testing.assert_array_equal(ours.get_xdata(), np.arange(2, 11))
    np.testing.assert_allclose(ours.get_ydata(), values["paper()"].reshape(9, 2).mean(axis=1))
    np.testing.assert_allclose(paper.get_ydata()[[0, -1]], [0.766, 0.761])
    # A metrics mapping per method works too (field picked, docs/BENCHMARK.md §2 rule applied).
    m = {"err3d": np.arange(views.size, dtype=float), "num_err_groups": np.tile([1, 0], 9)}
    fig = views_ablation(views, {"a": m}, field="err3d", paper=None)
    np.testing.assert_allclose(fig.axes[0].get_lines()[0].get_ydata(), np.arange(0, 18, 2))


def test_time_vs_count_says_it_is_the_padded_bucket_time():
    _, count, _, time_s = _grid()
    capacity = np.where(count <= 10, 10, int(count.max()))
    fig = time_vs_count(count, time_s, capacity=capacity)
    (ax,) = fig.axes
    assert "padded bucket" in ax.get_ylabel()
    assert "flat within a bucket" in fig.legends[0].get_title().get_text()
    bucket_lines = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":"]
    np.testing.assert_allclose(
        sorted(ln.get_xdata()[0] for ln in bucket_lines), np.unique(capacity)
    )
    assert any(t.get_text() == f"P = {int(count.max())}" for t in ax.texts)


def test_metrics_vs_sigma_notes_a_smaller_grid():
    sigma, _, metrics, _ = _grid()
    full = metrics_vs_sigma(sigma, metrics, fields=("pg_f1",))
    small = metrics_vs_sigma(sigma, metrics, fields=("pg_f1",), full_grid=False)
    assert "rough guide" not in full.get_suptitle()
    assert "rough guide" in small.get_suptitle() and "smaller grid" in small.get_suptitle()


def test_curves_take_per_method_scenes_and_many_methods():
    """Methods run on different scenes (a slow one on a sub-grid): σ, count and capacity as
    ``{method: (S_m,)}``; more than ten methods get distinct colours."""
    sigma, count, metrics, time_s = _grid()
    sub = (sigma == 0.0) | (sigma == 3.0)
    many = {f"m{i}": metrics["paper()"] for i in range(12)}
    many["sub"] = {f: v[sub] for f, v in metrics["reference()"].items()}
    sigmas = {**{k: sigma for k in many if k != "sub"}, "sub": sigma[sub]}
    fig = metrics_vs_sigma(sigmas, many, fields=("pg_f1",))
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    np.testing.assert_allclose(lines["sub"].get_xdata(), [0.0, 3.0])
    want = [metrics["reference()"]["pg_f1"][sigma == s].mean() for s in (0.0, 3.0)]
    np.testing.assert_allclose(lines["sub"].get_ydata(), want)
    colors = {tuple(lines[k].get_color()) for k in many}
    assert len(colors) == len(many)
    counts = {"paper()": count, "reference()": count[sub]}
    times = {"paper()": time_s["paper()"], "reference()": time_s["reference()"][sub]}
    fig = time_vs_count(counts, times, capacity={k: v for k, v in counts.items()})
    second = fig.axes[0].get_lines()[1]
    np.testing.assert_array_equal(second.get_xdata(), np.unique(count[sub]))
    with pytest.raises(ValueError, match="lacks"):
        metrics_vs_sigma({"paper()": sigma}, metrics, fields=("pg_f1",))
    views = {"a": np.array([2, 2, 3]), "b": np.array([3, 4])}
    fig = views_ablation(
        views, {"a": np.array([0.2, 0.4, 0.5]), "b": np.array([0.6, 0.8])}, paper=None
    )
    a_line, b_line = fig.axes[0].get_lines()
    np.testing.assert_allclose(a_line.get_ydata(), [0.3, 0.5])
    np.testing.assert_array_equal(b_line.get_xdata(), [3, 4])

"""The command line (``cdog-jax demo``) and the association figure."""

import jax
import numpy as np
import pytest

import cdog_jax
from cdog_jax.cli import main
from cdog_jax.synthetic import default_rig, generate_scene
from cdog_jax.viz import plot_association

METRIC_NAMES = ("G-F1", "mP-F1", "PG-P", "PG-R", "PG-F1", "3DErr", "BPE")


def test_demo_writes_png_and_prints_metrics(tmp_path, capsys):
    out = tmp_path / "d.png"
    code = main(["demo", "--points", "12", "--out", out])
    assert code in (0, None)
    assert out.is_file() and out.stat().st_size > 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = capsys.readouterr().out
    for name in METRIC_NAMES:
        assert name in text, name
    for word in ("views", "unassigned", "τ", "warm"):
        assert word in text.lower(), word
    assert str(out) in text


def test_demo_rejects_capacity_below_points(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        main(["demo", "--points", "12", "--capacity", "5", "--out", tmp_path / "d.png"])
    assert info.value.code == 2
    assert "--capacity" in capsys.readouterr().err


def test_requires_a_subcommand(capsys):
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2


@pytest.fixture(scope="module")
def tiny():
    """A 12-point scene on the built-in rig and its association (the shapes of the demo
    test above, so the compiled pipeline is reused)."""
    rig = default_rig()
    scene = generate_scene(jax.random.PRNGKey(3), rig, 12, 1.0, capacity=12)
    return rig, scene, cdog_jax.associate(rig, scene.xy, scene.mask, sigma=1.0)


@pytest.mark.parametrize("with_gt", [True, False])
def test_plot_association_tiny_scene(tmp_path, tiny, with_gt):
    rig, scene, result = tiny
    path = tmp_path / "tiny.png"
    gt = np.asarray(scene.points3d)[: int(scene.num_points)] if with_gt else None
    fig = plot_association(
        rig, scene.xy, scene.mask, result, points3d_gt=gt, title="extra line", path=path
    )
    assert path.is_file() and path.stat().st_size > 0
    axes = fig.get_axes()
    M = rig.num_views
    assert len(axes) == M + 1  # one panel per view, one 3D panel
    assert [ax.get_title(loc="left") for ax in axes[:M]] == [f"view {m}" for m in range(M)]
    lo, hi = axes[0].get_ylim()
    assert lo > hi  # image y axis points down
    assert axes[-1].name == "3d"
    assert "extra line" in fig._suptitle.get_text()


def test_plot_association_rejects_batched_result(tiny):
    rig, scene, result = tiny
    batched = jax.tree_util.tree_map(lambda a: a[None], result)
    with pytest.raises(ValueError, match="unbatched"):
        plot_association(rig, scene.xy, scene.mask, batched)


def test_calibrate_quick_end_to_end(tmp_path, capsys):
    out = tmp_path / "calibration.png"
    assert main(["calibrate", "--quick", "--out", out]) == 0
    text = capsys.readouterr().out
    row = next(line for line in text.splitlines() if line.startswith("| large"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    bpe_before, bpe_after = (float(v) for v in cells[4].split(" → "))
    pg_before, pg_after = (float(v) for v in cells[5].split(" (")[0].split(" → "))
    assert bpe_after < 0.1 * bpe_before  # the refined rig explains the detections
    assert pg_after > pg_before + 0.3  # and re-association with it recovers the groups
    assert out.stat().st_size > 0

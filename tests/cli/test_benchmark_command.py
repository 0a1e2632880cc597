"""``cdog-jax benchmark --quick`` end to end on a very small grid."""

import os

import numpy as np

from cdog_jax.benchmark import load_results
from cdog_jax.cli import main


def test_benchmark_quick_end_to_end(tmp_path, capsys):
    out = tmp_path / "bench"
    argv = ["benchmark", "--quick", "--sigmas", "0", "2", "--counts", "4", "--scenes", "1"]
    argv += ["--methods", "paper,reference", "--views", "0", "1", "2", "3", "--out", out]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "| σ (px) | method |" in text and "| 2 | reference |" in text and "PG-F1" in text
    result = load_results(out)
    assert result.configs == ("paper", "reference") and result.num_scenes == 2
    for name in (
        "results.npz",
        "results.csv",
        "results.json",
        "metrics_vs_sigma.png",
        "time_vs_count.png",
        "heatmaps_paper.png",
    ):
        assert os.path.getsize(out / name) > 0, name


def test_unknown_method_is_refused(capsys):
    try:
        main(["benchmark", "--methods", "paper,magic"])
    except SystemExit as e:
        assert e.code == 2
    assert "methods must be 'all' or a comma list" in capsys.readouterr().err


def test_benchmark_on_a_rig_file(tmp_path, capsys):
    from cdog_jax.io import save_rig
    from cdog_jax.synthetic import default_rig, visible_box

    rig = default_rig().select([0, 1, 2, 3])
    save_rig(tmp_path / "rig", rig, format="easyvis")
    out = tmp_path / "bench"
    argv = [
        "benchmark",
        "--quick",
        "--rig",
        str(tmp_path / "rig"),
        "--sigmas",
        "1",
        "--counts",
        "4",
        "--scenes",
        "1",
    ]
    argv += ["--methods", "paper", "--no-figures", "--no-timing", "--out", out]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "(4 views); image 640×480 px (guessed from K's principal points)" in text, text
    assert "(the region ≥ 2 of the views see)" in text
    assert "bucket 1/1 (capacity 4) done: 1/1 scenes" in text  # the progress display
    result = load_results(out)
    np.testing.assert_array_equal(result.rig["K"], np.asarray(rig.K))
    np.testing.assert_allclose(np.asarray(result.box), visible_box(rig, (640, 480)), rtol=1e-6)
    assert result.num_points[0] == 4


def test_benchmark_rig_file_with_explicit_box(tmp_path, capsys):
    from cdog_jax.io import save_rig
    from cdog_jax.synthetic import default_rig

    save_rig(
        tmp_path / "rig.json",
        default_rig().select([0, 1, 2, 3]),
        format="json",
        image_size=(640, 480),
    )
    out = tmp_path / "bench"
    argv = [
        "benchmark",
        "--quick",
        "--rig",
        str(tmp_path / "rig.json"),
        "--sigmas",
        "1",
        "--counts",
        "4",
    ]
    argv += ["--scenes", "1", "--methods", "paper", "--no-figures", "--no-timing", "--out", out]
    argv += ["--box", "-0.5", "-0.5", "0", "0.5", "0.5", "0.4", "--no-progress"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "image 640×480 px (the rig file)" in text and "(--box)" in text
    assert "bucket 1/1" not in text  # --no-progress: no report between buckets
    np.testing.assert_allclose(
        load_results(out).box, [[-0.5, -0.5, 0.0], [0.5, 0.5, 0.4]], rtol=1e-6
    )


def test_the_benchmark_runs_the_default_method_of_every_entry_point():
    import inspect

    from cdog_jax._method import method_argument
    from cdog_jax.cli._cli import build_parser

    default = inspect.signature(method_argument).parameters["default"].default
    args = build_parser().parse_args(["benchmark", "--quick"])
    assert args.methods[0] == default == "best" and "no_iqr" not in args.methods
    assert build_parser().parse_args(["associate", "--rig", "r", "--points", "p"]).method == default


def test_benchmark_on_a_rig_far_from_its_world_origin(tmp_path, capsys):
    """A rig file in UTM-like coordinates: the scenes are made and associated about the
    cameras' centre, which float32 holds, and a --box given in the file's world moves with
    it (the same scores as the rig near its origin)."""
    import json

    from cdog_jax.io import save_rig
    from cdog_jax.synthetic import default_rig

    rig = default_rig().select([0, 1, 2, 3])
    offset = np.array([5e5, 2.5e5, 10.0])
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    far = t - np.einsum("mij,j->mi", R, offset)  # X_cam = R (X_far - offset) + t
    (tmp_path / "far.json").write_text(
        json.dumps(
            {
                "views": [
                    {"K": K[m].tolist(), "R": R[m].tolist(), "t": far[m].tolist()} for m in range(4)
                ]
            }
        )
    )
    save_rig(tmp_path / "near.json", rig, format="json")
    common = ["benchmark", "--quick", "--sigmas", "1", "--counts", "6", "--scenes", "2"]
    common += ["--methods", "paper", "--no-figures", "--no-timing", "--no-progress"]
    box = np.array([-0.5, -0.5, 0.0, 0.5, 0.5, 0.4])
    results = {}
    for name, shift in (("near", np.zeros(3)), ("far", offset)):
        given = [str(v) for v in box + np.tile(shift, 2)]
        argv = [*common, "--rig", str(tmp_path / f"{name}.json"), "--box", *given]
        assert main([*argv, "--out", tmp_path / name]) == 0
        text = capsys.readouterr().out
        assert ("the cameras lie far from the rig's world origin" in text) == (name == "far")
        results[name] = load_results(tmp_path / name)
    near, far = results["near"], results["far"]
    assert near.num_scenes == far.num_scenes == 2
    m_near, m_far = near.metrics_of("paper"), far.metrics_of("paper")
    np.testing.assert_allclose(np.asarray(m_far.pg_f1), np.asarray(m_near.pg_f1), atol=0.05)
    assert np.all(np.asarray(m_far.pg_f1) > 0.5)

"""``cdog-jax benchmark --quick`` end to end on a very small grid."""

import os

from cdog_jax._cli import main
from cdog_jax.benchmark import load_results


def test_benchmark_quick_end_to_end(tmp_path, capsys):
    out = tmp_path / "bench"
    argv = ["benchmark", "--quick", "--sigmas", "0", "2", "--counts", "4", "--scenes", "1"]
    argv += ["--methods", "paper,reference", "--views", "0", "1", "2", "3", "--out", out]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "| σ (px) | method |" in text and "| 2 | reference |" in text and "PG-F1" in text
    result = load_results(out)
    assert result.configs == ("paper", "reference") and result.num_scenes == 2
    for name in ("results.npz", "results.csv", "results.json", "metrics_vs_sigma.png", "time_vs_count.png", "heatmaps_paper.png"):
        assert os.path.getsize(out / name) > 0, name


def test_unknown_method_is_refused(capsys):
    try:
        main(["benchmark", "--methods", "paper,magic"])
    except SystemExit as e:
        assert e.code == 2
    assert "methods must be a comma list" in capsys.readouterr().err

"""experiments/sigma_estimate.py runs end to end with --quick (a handful of tiny scenes), and
its purity count."""

import importlib.util
import math
import pathlib

import numpy as np

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "sigma_estimate.py"


def _load():
    spec = importlib.util.spec_from_file_location("sigma_estimate_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_sigma_estimate_quick(tmp_path, capsys):
    out = _load().main(["--quick", "--scenes", "1", "--json", str(tmp_path / "s.json")])
    assert (tmp_path / "s.json").stat().st_size > 0
    sets = [r["set"] for r in out["rows"]]
    assert any(s.startswith("grid") for s in sets) and any(s.startswith("robust") for s in sets)
    assert any(s.startswith("sparse") for s in sets) and any(s.startswith("heavy") for s in sets)
    for r in out["rows"]:
        assert r["scenes"] >= 1 and 0.0 <= r["fallback"] <= 1.0
        assert r["fallback"] == 1.0 or all(math.isfinite(v) and v > 0 for v in r["new"])
    assert out["purity"] == {}  # the association runs are left out of --quick
    nf = out["noise_free_one_point"]
    assert all(math.isfinite(v) for v in nf["new"]) and math.isfinite(nf["exact_zero"]["new"])
    assert "σ̂/σ, simple EM" in capsys.readouterr().out


def test_impure_share_counts_mixed_and_clutter_groups():
    labels = np.array([[[0, 1, 2, -1], [0, 1, 2, 3]]])
    instance = np.array([[[5, 6, -1, 7], [5, 7, -1, 8]]])
    mask = np.array([[[True, True, True, False], [True, True, True, True]]])
    # group 0: one point; group 1: two points; group 2: clutter; group 3: a singleton
    assert _load()._impure_share(labels, instance, mask) == (2, 4)

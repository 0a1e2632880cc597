"""experiments/robustness_realistic.py runs end to end with --quick (paper() only, tiny scenes)."""

import importlib.util
import math
import pathlib

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "robustness_realistic.py"


def _load():
    spec = importlib.util.spec_from_file_location("robustness_realistic_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_robustness_realistic_quick(tmp_path, capsys):
    script = _load()
    png = tmp_path / "r.png"
    out = script.main(["--quick", "--figure", str(png), "--json", str(tmp_path / "r.json")])
    assert png.stat().st_size > 0 and (tmp_path / "r.json").stat().st_size > 0
    assert out["presets"] == ["paper"]
    for name, fam in out["families"].items():
        rows = fam["rows"]
        assert (rows[0]["factor"], rows[0]["value"]) == ("tails", math.inf)
        assert {r["factor"] for r in rows} == set(script.FACTORS)
        for r in rows:
            for k in ("pg_f1", "g_f1", "recall", "joined"):
                assert 0.0 <= r["paper"][k] <= 1.0, (name, r)
            assert r["paper"]["sigma_ratio"] > 0
    # The clean skeleton level is easy: every joint is reconstructed within 10 cm.
    assert out["families"]["skeleton"]["rows"][0]["paper"]["recall"] == 1.0
    t = out["targets"]
    assert t["nu"] in script.FIT_NUS and t["sigma"] > 0 and len(t["rows"]) >= 1
    table = capsys.readouterr().out
    assert "| level | paper PG-F1 |" in table and "recall within 10 cm" in table


def test_the_fitted_gate_runs_with_sigma_per_scene():
    """The fitted gate's preset runs on skeletons with σ per (frame, joint) scene, and is
    refused with σ pooled per frame (the gate is fitted per scene)."""
    script = _load()
    family = script.FAMILIES["skeleton"]
    lv = script.levels(family, quick=True)[:2]  # the clean level and one other
    rig, batch = script.skeleton_batch(lv, 1, 2, family, script.SEED)
    scores = script.run_skeleton(family, "paper_fitted", batch, rig, sigma_pool="scene")
    rows = script.summarise({"paper_fitted": scores}, lv, 2)
    assert rows[0]["paper_fitted"]["recall"] == 1.0
    for r in rows:
        assert 0.0 <= r["paper_fitted"]["pg_f1"] <= 1.0, r
    with pytest.raises(ValueError, match="sigma_pool='scene'"):
        script.run_skeleton(family, "paper_fitted", batch, rig)


def test_the_shelf_errors_family_is_the_skeletons_with_the_detectors_errors():
    """Its scenes are the skeleton family's people with Shelf's missed joints and swaps: the
    same seed gives fewer detections; the presets run on it."""
    script = _load()
    lv = script.levels(script.FAMILIES["skeleton"], quick=True)[:1]
    _, plain = script.skeleton_batch(lv, 1, 2, script.FAMILIES["skeleton"], script.SEED)
    family = script.FAMILIES["shelf_errors"]
    rig, batch = script.skeleton_batch(lv, 1, 2, family, script.SEED)
    assert 0 < int(batch.mask.sum()) < int(plain.mask.sum())
    rows = script.summarise({"paper": script.run_skeleton(family, "paper", batch, rig)}, lv, 2)
    assert 0.5 < rows[0]["paper"]["recall"] <= 1.0

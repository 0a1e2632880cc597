"""Smoke test: experiments/stage_ablation.py runs on a tiny grid and reports every stage."""

import importlib.util
import json
import os

HERE = os.path.dirname(__file__)


def test_stage_ablation_tiny(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location(
        "stage_ablation", os.path.join(HERE, "..", "experiments", "stage_ablation.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "rows.json"
    rows = module.main(["--sigmas", "1", "--counts", "6", "--scenes", "1", "--out", str(out)])
    assert [r["stage"] for r in rows] == list(module.STAGES)
    assert all(0.0 <= r["pg_r"] <= 1.0 and 0.0 <= r["g_f1"] <= 1.0 for r in rows)
    assert json.loads(out.read_text()) == rows
    assert "+ regroup = extended()" in capsys.readouterr().out

"""Smoke test: experiments/stage_ablation.py runs on a tiny grid, the first and the last of
its rows (each row is a method of the same sweep; the whole list is compiled in one program,
which costs the suite half a minute), and refuses a row it does not have."""

import importlib.util
import json
import os

import pytest

HERE = os.path.dirname(__file__)


def test_stage_ablation_tiny(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location(
        "stage_ablation", os.path.join(HERE, "..", "experiments", "stage_ablation.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    names = list(module.STAGES)
    assert names[0] == "graph + split" and names[-1] == "+ regroup = extended()"
    chosen = [names[0], names[-1]]
    out = tmp_path / "rows.json"
    rows = module.main(
        ["--sigmas", "1", "--counts", "6", "--scenes", "1", "--stages", ",".join(chosen)]
        + ["--out", str(out)]
    )
    assert [r["stage"] for r in rows] == chosen
    assert all(0.0 <= r["pg_r"] <= 1.0 and 0.0 <= r["g_f1"] <= 1.0 for r in rows)
    assert json.loads(out.read_text()) == rows
    assert "+ regroup = extended()" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        module.main(["--stages", "no such"])
    assert "no row named 'no such'" in capsys.readouterr().err

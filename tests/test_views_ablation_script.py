"""experiments/views_ablation.py runs end to end on a tiny setting (k ∈ {2, 3})."""

import importlib.util
import json
import pathlib

import numpy as np

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "views_ablation.py"


def _load():
    spec = importlib.util.spec_from_file_location("views_ablation_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_views_ablation_tiny(tmp_path, capsys):
    script = _load()
    subs = script.draw_subsets(10, 3, 4, np.random.default_rng(0))
    assert (
        len(subs) == 4
        and len(set(subs)) == 4
        and all(len(s) == 3 and len(set(s)) == 3 for s in subs)
    )
    assert script.draw_subsets(10, 10, 3, np.random.default_rng(0)) == [tuple(range(10))]

    script.main(
        [
            "--views-range",
            "2",
            "3",
            "--counts",
            "10",
            "--scenes",
            "1",
            "--subsets",
            "1",
            "--methods",
            "paper,extended",
            "--out",
            str(tmp_path),
        ]
    )
    assert (tmp_path / "views_ablation.png").stat().st_size > 0
    out = json.loads((tmp_path / "views_ablation.json").read_text())
    assert [r["views"] for r in out["rows"]] == [2, 3]
    for r in out["rows"]:
        assert len(r["subsets"]) == 1 and len(r["subsets"][0]) == r["views"]
        assert r["num_scenes"] == {"paper": 1, "extended": 1}
        assert r["subsets_run"] == {"paper": 1, "extended": 1}
        assert r["paper_table_i_pg_f1"] == {2: 0.766, 3: 0.726}[r["views"]]
        for m in ("paper", "extended"):
            for f in ("pg_f1", "mp_f1", "g_f1"):
                assert 0.0 <= r[m][f] <= 1.0
    table = capsys.readouterr().out
    assert "| views | paper | extended | paper Table I |" in table and "**G-F1**" in table

"""experiments/robustness.py runs end to end with --quick (paper() only, 9 tiny scenes)."""

import importlib.util
import pathlib

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "robustness.py"


def _load():
    spec = importlib.util.spec_from_file_location("robustness_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_robustness_quick(tmp_path, capsys):
    script = _load()
    assert script.levels()[:5] == [(d, 0.0) for d in script.DROP_RATES]
    assert script.levels()[5:] == [(0.0, c) for c in script.CLUTTER_RATES[1:]]
    png = tmp_path / "robustness.png"
    out = script.main(["--quick", "--figure", str(png), "--json", str(tmp_path / "r.json")])
    assert png.stat().st_size > 0 and (tmp_path / "r.json").stat().st_size > 0
    assert out["configs"] == ["paper"] and len(out["rows"]) == len(script.levels())
    for r in out["rows"]:
        assert r["num_scenes"] == 1
        assert 0.0 <= r["g_f1_max"] <= 1.0
        for f in ("pg_f1", "mp_f1", "g_f1"):
            assert 0.0 <= r["paper"][f] <= 1.0
    clean = out["rows"][0]
    assert clean["drop_rate"] == clean["clutter_rate"] == 0.0 and clean["g_f1_max"] == 1.0
    table = capsys.readouterr().out
    assert "| drop (%) | clutter / view | paper PG-F1 |" in table and "truth G-F1" in table

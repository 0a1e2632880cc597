"""experiments/temporal_prior.py runs end to end with --quick (one short sequence, paper() only,
the prior off, and on with max_gap=1)."""

import importlib.util
import pathlib

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "temporal_prior.py"


def test_temporal_prior_quick(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("temporal_prior_script", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = script.main(["--quick", "--json", str(tmp_path / "t.json")])
    assert (tmp_path / "t.json").stat().st_size > 0
    assert [(r["preset"], r["prior"], r["max_gap"]) for r in out["rows"]] == [
        ("paper", p, g) for p, g in script.QUICK_CONDITIONS
    ]
    for r in out["rows"]:
        assert (
            0.0 <= r["recall"] <= 1.0
            and 0.0 <= r["joined"] <= 1.0
            and r["switches_per_track"] >= 0.0
        ), r
        assert r["tracks_per_joint"] >= 1.0 and (r["prior"] or r["recovered"] == 0), r
    assert out["rows"][0]["recovered"] == 0 and 0.0 < out["dropped_share"] < 0.5
    assert "| paper | on | 1 |" in capsys.readouterr().out

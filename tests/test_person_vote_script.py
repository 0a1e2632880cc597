"""experiments/person_vote.py runs end to end with --quick (paper() only, two frames)."""

import importlib.util
import pathlib

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "person_vote.py"


def test_person_vote_quick(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("person_vote_script", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = script.main(["--quick", "--json", str(tmp_path / "p.json")])
    assert (tmp_path / "p.json").stat().st_size > 0
    rows = {r["vote"]: r for r in out["rows"]}
    assert set(rows) == {False, True} and all(r["preset"] == "paper" and r["case"] == "targets" for r in rows.values())
    for r in rows.values():
        assert 0.0 <= r["joined"] <= 1.0 and 0.0 <= r["recall"] <= 1.0
    assert rows[True]["joined"] <= rows[False]["joined"]
    assert "| targets | paper |" in capsys.readouterr().out


def test_per_view_instances_permute_people_per_view():
    import numpy as np
    from types import SimpleNamespace

    spec = importlib.util.spec_from_file_location("person_vote_script", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    J = 17
    instance = np.array([[[0, J, 2 * J + 1, -1, 5]]] * 2).reshape(1, 2, 5)  # people 0, 1, 2, clutter, person 0
    kind = np.array([[[0, 0, 0, 2, 1]] * 2])
    frames = SimpleNamespace(instance=instance, kind=kind, mask=np.ones((1, 2, 5), bool))
    got = script.per_view_instances(frames, 0)
    assert got[0, :, 3].tolist() == [-1, -1]  # clutter: unknown
    for m in range(2):
        assert len(set(got[0, m, :3].tolist())) == 3 and got[0, m, 0] == got[0, m, 4] - script.MAX_PEOPLE  # the double's skeleton

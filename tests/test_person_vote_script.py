"""experiments/person_vote.py: its tables and its per-view instance index (the full run
compiles the skeleton scenes' programs: run the script itself, ``--quick`` for a small one)."""

import importlib.util
import pathlib

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "person_vote.py"


def _script():
    spec = importlib.util.spec_from_file_location("person_vote_script", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    return script


def test_tables_pair_each_run_with_its_vote():
    script = _script()
    row = dict(
        case="targets",
        preset="paper",
        recall=0.9,
        joined=0.03,
        pg_f1=0.8,
        seconds=1.0,
        vote_ms_per_frame=2.0,
    )
    out = {
        "nu": 2.5,
        "sigma": 5.21,
        "frames_total": 2,
        "sequences": 1,
        "frames": 2,
        "rows": [dict(row, vote=False), dict(row, vote=True, joined=0.0, recall=0.95)],
    }
    assert (
        "| targets | paper | 0.900 → 0.950 | 3.00 % → 0.00 % | 0.800 → 0.800 | 2.0 |"
        in script.markdown(out)
    )
    real = dict(
        trial="T",
        people=2,
        preset="best",
        points=10,
        detections=20,
        assigned=18,
        err_median=1.0,
        err_p90=2.0,
        visible_exact=0.5,
    )
    text = script.markdown_pose2sim(
        [dict(real, vote=False), dict(real, vote=True, points=9, moved=3)]
    )
    assert "| T | 2 | best | 10 → 9 | 0.900 → 0.900 |" in text and "| 3 of 20 |" in text


def test_per_view_instances_permute_people_per_view():
    from types import SimpleNamespace

    import numpy as np

    script = _script()
    J = 17
    instance = np.array([[[0, J, 2 * J + 1, -1, 5]]] * 2).reshape(
        1, 2, 5
    )  # people 0, 1, 2, clutter, person 0
    kind = np.array([[[0, 0, 0, 2, 1]] * 2])
    frames = SimpleNamespace(instance=instance, kind=kind, mask=np.ones((1, 2, 5), bool))
    got = script.per_view_instances(frames, 0)
    assert got[0, :, 3].tolist() == [-1, -1]  # clutter: unknown
    for m in range(2):
        assert (
            len(set(got[0, m, :3].tolist())) == 3
            and got[0, m, 0] == got[0, m, 4] - script.MAX_PEOPLE
        )  # the double's skeleton

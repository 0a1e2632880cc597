"""The notebook-style walkthrough (experiments/walkthrough.py) runs end to end on a small
scene: associate, the gradient of the BPE w.r.t. the cameras, refinement of a drifted rig
(the script asserts that the refinement lowers the BPE and halves the rotation error)."""

import os
import runpy
import sys

HERE = os.path.dirname(__file__)


def test_walkthrough_runs(monkeypatch, capsys):
    path = os.path.join(HERE, "..", "experiments", "walkthrough.py")
    monkeypatch.setattr(sys, "argv", [path, "--points", "30"])
    runpy.run_path(path, run_name="__main__")
    text = capsys.readouterr().out
    assert "groups; PG-F1" in text and "d BPE / d focal of view 0" in text and "rotation error" in text

"""examples/walkthrough.ipynb runs from top to bottom in a fresh kernel (nbclient): it
associates a 30-point scene, draws the four figures, differentiates the BPE and refines a
drifted rig (a cell asserts that the refinement lowers the BPE and halves the rotation
error), then tracks two walking people frame by frame. The notebook is the one source: what users open is what runs here."""

import os

import nbformat
from nbclient import NotebookClient

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))


def test_walkthrough_notebook_executes(monkeypatch):
    # The kernel is a new process: it must import this checkout's cdog_jax.
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join(filter(None, [ROOT, os.environ.get("PYTHONPATH")]))
    )
    monkeypatch.setenv("PYDEVD_DISABLE_FILE_VALIDATION", "1")
    nb = nbformat.read(os.path.join(ROOT, "examples", "walkthrough.ipynb"), as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs = []  # the stored outputs must not stand in for a run
    NotebookClient(
        nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": ROOT}}
    ).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    for expected in (
        "10 views",
        "groups; PG-F1",
        "d BPE / d focal of view 0",
        "rotation error",
        "frame 4: ",
    ):
        assert expected in text, expected
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 4  # association, epipolar lines, BPE histogram, rays

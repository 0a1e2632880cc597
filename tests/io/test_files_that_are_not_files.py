"""Files that are not files: a FIFO, a device or an oversized file is refused before it is
read (a FIFO would block forever, /dev/zero would be read until memory ran out)."""

import os

import pytest

import cdog_jax.io._errors as errors
from cdog_jax.cli import main
from cdog_jax.io import InputError, load_detections, load_keypoint_table, load_rig


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
@pytest.mark.parametrize(
    ("reader", "name"),
    [
        (load_rig, "rig.json"),
        (load_rig, "rig.npz"),
        (load_detections, "points.json"),
        (load_keypoint_table, "table.csv"),
    ],
)
def test_a_fifo_is_refused_at_once(tmp_path, reader, name):
    fifo = tmp_path / name
    os.mkfifo(fifo)
    with pytest.raises(InputError, match=f"{name}: not a regular file"):
        reader(fifo)


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero")
def test_a_device_is_refused_with_one_line(capsys):
    with pytest.raises(InputError, match="/dev/zero: not a regular file"):
        load_rig("/dev/zero", format="json")
    assert main(["rig", "/dev/zero", "--rig-format", "json"]) == 2
    assert capsys.readouterr().err == (
        "cdog-jax: error: /dev/zero: not a regular file (a pipe, a device or a socket); "
        "files are read whole, so they must be regular files\n"
    )


def test_a_file_above_the_size_limit_is_refused_before_reading(tmp_path, monkeypatch):
    path = tmp_path / "points.json"
    path.write_text('{"views": [[[1, 2]], [[3, 4]]]}')
    assert load_detections(path).mask.shape == (1, 2, 1)
    monkeypatch.setattr(errors, "MAX_INPUT_BYTES", 10)
    with pytest.raises(
        InputError, match=r"points\.json: 31 bytes; a file read whole may hold at most 10 bytes$"
    ):
        load_detections(path)

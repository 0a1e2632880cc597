"""``.trc`` marker files (OpenSim, Pose2Sim): the header as those tools read it, missing
markers as empty fields, the Z-up to Y-up turn, a round trip, and refusals."""

import numpy as np
import pytest

from cdog_jax.io import InputError, load_trc, save_trc

NAMES = ("Nose", "Neck", "RWrist")


def _markers():
    X = np.arange(4 * 3 * 3, dtype=np.float64).reshape(4, 3, 3) / 7.0
    X[1, 2] = np.nan  # RWrist not seen in frame 2
    return X


def test_header_rows_and_missing_markers(tmp_path):
    path = tmp_path / "walk.trc"
    save_trc(path, _markers(), NAMES, rate=25, units="m")
    lines = path.read_text().split("\n")
    assert lines[0] == "PathFileType\t4\t(X/Y/Z)\twalk.trc"
    assert lines[1].split("\t") == [
        "DataRate",
        "CameraRate",
        "NumFrames",
        "NumMarkers",
        "Units",
        "OrigDataRate",
        "OrigDataStartFrame",
        "OrigNumFrames",
    ]
    assert lines[2].split("\t") == ["25", "25", "4", "3", "m", "25", "1", "4"]
    assert lines[3] == "Frame#\tTime\tNose\t\t\tNeck\t\t\tRWrist"
    assert lines[4] == "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\tX3\tY3\tZ3"
    assert lines[5] == ""
    row = lines[7].split("\t")
    assert (
        row[:2] == ["2", "0.04"]
        and row[-3:] == ["", "", ""]
        and float(row[2]) == _markers()[1, 0, 0]
    )
    assert len(lines) == 6 + 4 + 1 and lines[-1] == ""


def test_round_trip_and_z_up(tmp_path):
    X = _markers()
    save_trc(tmp_path / "a.trc", X, NAMES, rate=30.5, units="mm")
    back = load_trc(tmp_path / "a.trc")
    np.testing.assert_array_equal(back.markers, X)  # repr: exact; NaN where not seen
    assert back.names == NAMES and back.rate == 30.5 and back.units == "mm"
    np.testing.assert_array_equal(back.frame, [1, 2, 3, 4])
    np.testing.assert_allclose(back.time, np.arange(4) / 30.5)
    save_trc(tmp_path / "y.trc", X, NAMES, rate=30, z_up=True)
    turned = load_trc(tmp_path / "y.trc").markers
    np.testing.assert_array_equal(turned, X[..., [1, 2, 0]])  # Z (up) becomes Y
    R = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]])
    assert np.linalg.det(R) == 1.0  # a rotation, not a mirror


@pytest.mark.parametrize(
    "names, kwargs, message",
    [
        (("a", "b"), {}, "3 markers need 3 names"),
        (("a", "a", "b"), {}, "distinct"),
        (("a", "b\tc", "d"), {}, "without tabs"),
        (NAMES, {"rate": 0}, "rate must be"),
        (NAMES, {"rate": True}, "rate must be"),
        (NAMES, {"units": "m m"}, "units must be"),
    ],
)
def test_bad_arguments_refused(tmp_path, names, kwargs, message):
    with pytest.raises(ValueError, match=message):
        save_trc(tmp_path / "x.trc", _markers(), names, **{"rate": 30, **kwargs})
    assert not (tmp_path / "x.trc").exists()


def test_bad_markers_refused(tmp_path):
    with pytest.raises(ValueError, match=r"\(F, K, 3\)"):
        save_trc(tmp_path / "x.trc", np.zeros((4, 3, 2)), NAMES, rate=30)
    X = _markers()
    X[0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="infinite"):
        save_trc(tmp_path / "x.trc", X, NAMES, rate=30)


def test_bad_files_refused(tmp_path):
    (tmp_path / "no.trc").write_text("hello\n1\n2\n3\n4\n")
    with pytest.raises(InputError, match="not a TRC file"):
        load_trc(tmp_path / "no.trc")
    save_trc(tmp_path / "ok.trc", _markers(), NAMES, rate=30)
    text = (tmp_path / "ok.trc").read_text().replace("\t0.0\t", "\tzero\t", 1)
    (tmp_path / "bad.trc").write_text(text)
    with pytest.raises(InputError, match="line 7: a value is not a number"):
        load_trc(tmp_path / "bad.trc")

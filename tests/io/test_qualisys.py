"""Qualisys .qca.txt calibrations: read as Pose2Sim 0.7.2 converts them (its steps redone
here literally), found by suffix, and malformed files named."""

import numpy as np
import pytest

from cdog_jax.io import InputError, load_rig
from cdog_jax.io._rig_files import FORMATS

CAMERA = """    <camera active="1" avg-residual="0.4" model="{model}" point-count="9" serial="{serial}" viewrotation="0">
      <fov_video bottom="{bottom}" left="{left}" right="{right}" top="{top}"/>
      <transform {transform}/>
      <intrinsic centerPointU="{cu}" centerPointV="{cv}" focalLengthU="{fu}" focalLengthV="{fv}" focallength="9.3"
        radialDistortion1="{k1}" radialDistortion2="{k2}" radialDistortion3="0.0" skew="0"
        tangentalDistortion1="{p1}" tangentalDistortion2="{p2}"/>
    </camera>
"""


def _pose2sim(M, C_mm, fu, fv, cu, cv, left, top):
    """Pose2Sim's read_qca + world_to_camera_persp + rotate_cam(ang_x=π), step by step."""
    R_read = M.T  # "by-column to by-line"
    T = np.asarray(C_mm) / 1000
    r, t = R_read.T, -R_read.T @ T  # world_to_camera_persp
    a = np.pi
    r_ax = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    K = np.array([[fu / 64, 0, cu / 64 - left], [0, fv / 64, cv / 64 - top], [0, 0, 1]])
    return K, r_ax @ r, r_ax @ t


def _write(path, cams):
    body = "".join(CAMERA.format(**c) for c in cams)
    path.write_text(
        f"<?xml version='1.0' encoding='ASCII'?>\n<calibration>\n  <cameras>\n{body}  </cameras>\n</calibration>\n"
    )


def _cams():
    rng = np.random.default_rng(3)
    out = []
    for k, serial in enumerate(["cam_10", "cam_2", "marker_1"]):
        M, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        M *= np.sign(np.linalg.det(M))
        C = rng.uniform(-3000, 3000, 3)
        transform = " ".join(
            f'r{i + 1}{j + 1}="{float(M[i, j])!r}"' for i in range(3) for j in range(3)
        )
        transform += f' x="{float(C[0])!r}" y="{float(C[1])!r}" z="{float(C[2])!r}"'
        out.append(
            dict(
                model="none" if k < 2 else "Miqus",
                serial=serial,
                left=8 * k,
                top=4 * k,
                right=1087 + 8 * k,
                bottom=1919 + 4 * k,
                transform=transform,
                cu=34000.0 + 100 * k,
                cv=61000.0,
                fu=107600.0 + 50 * k,
                fv=107500.0,
                k1=-0.046,
                k2=0.14,
                p1=0.0006,
                p2=-0.0007,
                M=M,
                C=C,
            )
        )
    return out


def test_qualisys_as_pose2sim_converts_it(tmp_path):
    assert "qualisys" in FORMATS
    cams = _cams()
    path = tmp_path / "Calib.qca.txt"
    _write(path, cams)
    rf = load_rig(path)  # format from the suffix; float32 rig
    assert rf.names == ("cam_2", "cam_10")  # natural order; the marker camera is left out
    assert rf.image_size == (1088, 1920)
    for view, c in zip((0, 1), (cams[1], cams[0])):
        K, R, t = _pose2sim(c["M"], c["C"], c["fu"], c["fv"], c["cu"], c["cv"], c["left"], c["top"])
        np.testing.assert_allclose(np.asarray(rf.rig.K[view]), K, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(np.asarray(rf.rig.R[view]), R, atol=1e-6)
        np.testing.assert_allclose(np.asarray(rf.rig.t[view]), t, atol=1e-5)
        np.testing.assert_allclose(
            rf.dist[view], np.array([-0.046, 0.14, 0.0006, -0.0007, 0.0]) / 64
        )
        # The camera centre is the transform's position, in metres.
        R32, t32 = np.asarray(rf.rig.R[view], np.float64), np.asarray(rf.rig.t[view], np.float64)
        np.testing.assert_allclose(-R32.T @ t32, c["C"] / 1000, atol=1e-5)


def test_qualisys_malformed_files_named(tmp_path):
    cams = _cams()[:2]
    cams[1]["transform"] = cams[1]["transform"].replace('r11="', 'q11="')
    path = tmp_path / "bad.qca.txt"
    _write(path, cams)
    with pytest.raises(
        InputError, match=r"bad\.qca\.txt: camera 'cam_2': <transform> has no attribute 'r11'"
    ):
        load_rig(path)
    path.write_text("<calibration><cameras>")
    with pytest.raises(InputError, match="invalid XML"):
        load_rig(path)

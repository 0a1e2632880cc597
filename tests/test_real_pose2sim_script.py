"""experiments/real_pose2sim.py on a tiny demo-like folder the test writes (no download):
a Qualisys calibration of 4 cameras and OpenPose BODY_25B files of two people over 2
frames; every joint of both people is found, with small reprojection errors, and the
figure and the results table are written."""

import json
import os
import runpy

import numpy as np

HERE = os.path.dirname(__file__)
CAMERA = """<camera active="1" avg-residual="0.4" model="none" point-count="9" serial="cam_{k}" viewrotation="0">
<fov_video bottom="479" left="0" right="639" top="0"/>
<transform {transform}/>
<intrinsic centerPointU="{cu}" centerPointV="{cv}" focalLengthU="{f}" focalLengthV="{f}" radialDistortion1="0"
 radialDistortion2="0" radialDistortion3="0" tangentalDistortion1="0" tangentalDistortion2="0"/>
</camera>
"""


def _look_at(c, target):
    z = target - c
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


def _write_demo(root, rng):
    K = np.array([[900.0, 0, 320], [0, 900, 240], [0, 0, 1]])
    cams, body = [], ""
    for k in range(4):
        a = 2 * np.pi * k / 4 + 0.3
        c = np.array([4 * np.cos(a), 4 * np.sin(a), 1.6])
        R = _look_at(c, np.array([0.0, 0.0, 1.0]))
        Q = np.diag([1.0, -1.0, -1.0]) @ R  # Qualisys camera axes (as Pose2Sim converts them)
        transform = " ".join(
            f'r{i + 1}{j + 1}="{float(Q[i, j])!r}"' for i in range(3) for j in range(3)
        )
        transform += "".join(f' {n}="{float(v) * 1000!r}"' for n, v in zip("xyz", c))
        body += CAMERA.format(k=k + 1, transform=transform, cu=320 * 64, cv=240 * 64, f=900 * 64)
        cams.append((R, -R @ c))
    calib = os.path.join(root, "S00_Calibration")
    os.makedirs(calib)
    with open(os.path.join(calib, "Calib.qca.txt"), "w") as f:
        f.write(f"<calibration><cameras>\n{body}</cameras></calibration>\n")
    pose = os.path.join(root, "S00_P01_MultiParticipants", "S00_P01_T02_Participants1-2", "pose")
    for frame in range(2):
        X = np.stack(
            [c + rng.uniform(-0.3, 0.3, (25, 3)) for c in ([-0.7, 0.0, 1.0], [0.7, 0.0, 1.0])]
        )  # (2, 25, 3)
        for k, (R, t) in enumerate(cams):
            h = (X @ R.T + t) @ K.T
            xy = h[..., :2] / h[..., 2:] + rng.normal(0, 0.3, (2, 25, 2))
            people = [
                {
                    "pose_keypoints_2d": np.concatenate([p, np.full((25, 1), 0.9)], 1)
                    .ravel()
                    .tolist()
                }
                for p in xy[:: 1 if k % 2 else -1]
            ]
            folder = os.path.join(pose, f"cam{k + 1:02d}_json")
            os.makedirs(folder, exist_ok=True)
            with open(os.path.join(folder, f"cam{k + 1:02d}.{frame:04d}.json"), "w") as f:
                json.dump({"version": 1.3, "people": people}, f)


def test_real_pose2sim_processing(tmp_path, capsys):
    demo = tmp_path / "S00_Demo_Session"
    _write_demo(str(demo), np.random.default_rng(0))
    script = runpy.run_path(os.path.join(HERE, "..", "experiments", "real_pose2sim.py"))
    figure, results = tmp_path / "frame.png", tmp_path / "RESULTS.md"
    stats = script["main"](
        [
            "--demo-dir",
            str(demo),
            "--presets",
            "paper",
            "--figure",
            str(figure),
            "--results",
            str(results),
            "--frame",
            "1",
            "--sigma-pools",
            "paper",
        ]
    )
    s = stats["S00_P01_T02_Participants1-2", "paper"]
    assert s["frames"] == 2 and s["detections"] == 2 * 4 * 50
    assert s["points"] == 2 * 50 and s["exact"] == 1.0 and s["visible_exact"] == 1.0
    assert s["err_median"] < 1.0
    assert figure.stat().st_size > 10_000
    assert "| S00_P01_T02_Participants1-2 | 2 | paper | 2 | 400 | 100 |" in results.read_text()
    assert "Figure:" in capsys.readouterr().out
    # The σ table: the two-participant trial again, σ pooled each way and given; pooled per
    # frame is the table's own run above.
    rows = {k[3]: v for k, v in stats.items() if len(k) == 4}
    assert list(rows) == [
        "pooled per frame (default)",
        "pooled over all frames",
        "per (frame, joint) scene",
        "given 8 px",
    ]
    assert rows["pooled per frame (default)"] == s
    assert rows["given 8 px"]["sigma_median"] == 8.0
    assert all(r["points"] == 2 * 50 for r in rows.values())
    assert "| given 8 px | 8.0 | 100 |" in results.read_text()

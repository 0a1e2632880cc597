"""``cdog-jax track`` in a real pipe: each frame's line is written and flushed before the next
frame is sent, a bad line gets one error line and the stream goes on, the end of input
ends the command with status 0; the answers are the live associator's."""

import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from cdog_jax import LiveAssociator
from cdog_jax.io import save_rig
from cdog_jax.synthetic import SKELETON_JOINTS, default_rig, generate_skeleton_scenes

M, J = 3, 17


@pytest.fixture(scope="module")
def stream(tmp_path_factory):
    """A 3-camera rig file and three frames of two walking people as JSON lines (joint
    names as classes)."""
    from cdog_jax.synthetic import SKELETON_JOINTS

    folder = tmp_path_factory.mktemp("track")
    rig = default_rig(num_views=M)
    save_rig(str(folder / "rig.json"), rig, format="json", image_size=(640, 480))
    sk = generate_skeleton_scenes(jax.random.PRNGKey(2), rig, 2, 1.0, num_frames=3).frames
    xy, mask, cls = (np.asarray(a) for a in (sk.xy, sk.mask, sk.class_id))
    lines = []
    for f in range(3):
        views = [
            [[float(v) for v in xy[f, m, i]] for i in np.flatnonzero(mask[f, m])] for m in range(M)
        ]
        names = [
            [SKELETON_JOINTS[cls[f, m, i]] for i in np.flatnonzero(mask[f, m])] for m in range(M)
        ]
        lines.append(json.dumps({"views": views, "classes": names, "frame": 100 + f}))
    return folder / "rig.json", lines, rig, (xy, mask, cls)


def test_frames_stream_through_a_pipe(stream):
    rig_path, lines, rig, (xy, mask, cls) = stream
    command = [
        sys.executable,
        "-m",
        "cdog_jax",
        "track",
        "--rig",
        str(rig_path),
        "--keypoints",
        "COCO_17",
    ]
    # One device: the pipe is what is tested here (a live frame on two devices is
    # tests/test_devices.py's), and on two the first frame compiles once per device.
    env = dict(os.environ, CDOG_JAX_CPU_DEVICES="1")
    with subprocess.Popen(
        command,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    ) as child:
        answers = []
        bad = ("{not json", '{"views": [[[1, 2]]]}', '{"views": [[[1, 2]]], "clases": [[0]]}')
        for line in (lines[0], bad[0], lines[1], bad[1], bad[2], lines[2]):
            child.stdin.write(line + "\n")
            child.stdin.flush()
            answers.append(
                json.loads(child.stdout.readline())
            )  # written before the next line is sent
        child.stdin.close()
        assert child.wait(timeout=120) == 0, child.stderr.read()
        assert child.stdout.read() == ""
    assert answers[1] == {"line": 2, "error": answers[1]["error"]} and answers[1][
        "error"
    ].startswith("line 2: not JSON")
    assert answers[3]["line"] == 4 and "views" in answers[3]["error"]
    assert answers[4]["line"] == 5 and 'unknown key "clases"' in answers[4]["error"]
    frames = [answers[0], answers[2], answers[5]]
    assert [a["frame"] for a in frames] == [100, 101, 102]
    # The same as the live associator on the same frames (slots are the input's order).
    live = LiveAssociator(rig, class_names=list(SKELETON_JOINTS))
    for f, answer in enumerate(frames):
        order = [np.flatnonzero(mask[f, m]) for m in range(M)]
        out = live.update(xy[f], mask[f], classes=np.where(mask[f], cls[f], 0))
        assert len(answer["groups"]) == len(out.groups) > 5
        for group, g in zip(answer["groups"], range(len(out.groups))):
            members = [
                [m, int(np.flatnonzero(order[m] == s)[0])]
                for m, s in enumerate(out.groups[g])
                if s >= 0
            ]
            assert group["members"] == members and group["track"] == int(out.track_id[g])
            np.testing.assert_allclose(group["point"], out.points3d[g], atol=1e-5)


def test_a_rig_far_from_its_world_origin_streams_world_points(
    stream, tmp_path, monkeypatch, capsys
):
    """A rig file in UTM-like coordinates: the command associates about the cameras'
    centre and each line's points are in the file's world (the near rig's, moved)."""
    import io

    from cdog_jax.cli import main

    rig_path, lines, rig, _ = stream
    offset = np.array([4e5, 6e6, 30.0])
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    U, _, Vt = np.linalg.svd(R)
    R = U @ Vt  # orthonormal in float64: float32's 1e-7 would move a centre 6e6 out by 0.6
    far = t - np.einsum("mij,j->mi", R, offset)
    views = [{"K": K[m].tolist(), "R": R[m].tolist(), "t": far[m].tolist()} for m in range(M)]
    (tmp_path / "far.json").write_text(json.dumps({"views": views}))
    answers = []
    for path in (rig_path, tmp_path / "far.json"):
        monkeypatch.setattr("sys.stdin", io.StringIO(lines[0] + "\n"))
        assert main(["track", "--rig", str(path), "--keypoints", "COCO_17"]) == 0
        answers.append(json.loads(capsys.readouterr().out))
    near, moved = answers
    assert [g["members"] for g in moved["groups"]] == [g["members"] for g in near["groups"]]
    np.testing.assert_allclose(
        [np.asarray(g["point"]) - offset for g in moved["groups"]],
        [g["point"] for g in near["groups"]],
        atol=1e-3,
    )


def test_a_held_sigma_streams_the_live_associators_answers(stream, monkeypatch, capsys):
    """``--sigma held``: the first frame's σ for every later line, the answers of a
    ``LiveAssociator(sigma="held")``."""
    import io

    from cdog_jax.cli import main

    rig_path, lines, rig, (xy, mask, cls) = stream
    monkeypatch.setattr("sys.stdin", io.StringIO("\n".join(lines) + "\n"))
    assert main(["track", "--rig", str(rig_path), "--keypoints", "COCO_17", "--sigma", "held"]) == 0
    answers = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    live = LiveAssociator(rig, class_names=list(SKELETON_JOINTS), sigma="held")
    for f, answer in enumerate(answers):
        out = live.update(xy[f], mask[f], classes=np.where(mask[f], cls[f], 0))
        assert answer["sigma_px"] == round(live.held_sigma, 4) == round(out.sigma_px, 4)
        assert [g["track"] for g in answer["groups"]] == out.track_id.tolist()


def test_track_command_errors_are_one_line(tmp_path, capsys):
    from cdog_jax.cli import main

    assert main(["track", "--rig", str(tmp_path / "missing.json")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert main(["track", "--rig", "x.json", "--class-names", "a,,b"]) == 2
    assert "--class-names" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: its usage, then one line
        main(["track", "--rig", "x.json", "--sigma", "often"])
    assert '"auto", "held" or a number' in capsys.readouterr().err.splitlines()[-1]
    assert main(["track", "--rig", "x.json", "--sigma", "-1"]) == 2
    assert capsys.readouterr().err.count("\n") == 1

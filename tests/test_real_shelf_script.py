"""experiments/real/shelf.py and shelf_score.py on a tiny made-up stand-in for Shelf, in
Shelf's file formats (calibration.json, detection/<v>.txt with BODY_25 candidates and PAF
scores, gt.txt): two people seen by five cameras over three frames."""

import json
import os
import runpy

import numpy as np
import pytest

from cdog_jax.synthetic._rig import look_at_rotation

HERE = os.path.dirname(os.path.abspath(__file__))
REAL = os.path.join(HERE, "..", "experiments", "real")
shelf = runpy.run_path(os.path.join(REAL, "shelf.py"), run_name="shelf")
score = runpy.run_path(os.path.join(REAL, "shelf_score.py"), run_name="shelf_score")

SIZE = (1032, 776)
# A standing person's BODY_25 joints (metres, z up; its right side at -x, so it faces -y).
TEMPLATE = np.array(
    [
        (0, 0.1, 1.65),
        (0, 0, 1.5),
        (-0.2, 0, 1.45),
        (-0.25, 0, 1.2),
        (-0.28, 0.05, 0.95),
        (0.2, 0, 1.45),
        (0.25, 0, 1.2),
        (0.28, 0.05, 0.95),
        (0, 0, 0.95),
        (-0.1, 0, 0.95),
        (-0.11, 0.02, 0.5),
        (-0.12, 0, 0.08),
        (0.1, 0, 0.95),
        (0.11, 0.02, 0.5),
        (0.12, 0, 0.08),
        (-0.04, 0.09, 1.7),
        (0.04, 0.09, 1.7),
        (-0.08, 0, 1.68),
        (0.08, 0, 1.68),
        (0.13, 0.15, 0.02),
        (0.17, 0.13, 0.02),
        (0.12, -0.05, 0.03),
        (-0.13, 0.15, 0.02),
        (-0.17, 0.13, 0.02),
        (-0.12, -0.05, 0.03),
    ]
) * (1, -1, 1)


def _cameras(M=5):
    """``M`` cameras on a circle of radius 4 m, 2.5 m up, looking at (0, 0, 1)."""
    K = np.array([[1000.0, 0, SIZE[0] / 2], [0, 1000.0, SIZE[1] / 2], [0, 0, 1]])
    Ks, Rs, ts = [], [], []
    for m in range(M):
        a = 2 * np.pi * m / M
        centre = np.array([4 * np.cos(a), 4 * np.sin(a), 2.5])
        R = look_at_rotation(centre, (0.0, 0.0, 1.0))
        Ks.append(K)
        Rs.append(R)
        ts.append(-R @ centre)
    return np.array(Ks), np.array(Rs), np.array(ts)


def _people(frames=3):
    """``(F, 2, 25, 3)``: two people walking slowly apart."""
    out = []
    for f in range(frames):
        out.append([TEMPLATE + (-0.8 - 0.05 * f, 0, 0), TEMPLATE + (0.8, 0.3 + 0.05 * f, 0)])
    return np.array(out)


def _write_standin(folder, frames=3):
    K, R, t = _cameras()
    people = _people(frames)
    cams = {
        str(m): {
            "K": K[m].reshape(-1).tolist(),
            "RT": np.c_[R[m], t[m]].reshape(-1).tolist(),
            "imgSize": list(SIZE),
        }
        for m in range(5)
    }
    os.makedirs(os.path.join(folder, "detection"))
    with open(os.path.join(folder, "calibration.json"), "w") as f:
        json.dump(cams, f)
    rng = np.random.default_rng(0)
    order_by_view = []
    for m in range(5):
        lines = [f"4\t{frames}"]
        orders = []
        for f in range(frames):
            cam = (R[m] @ people[f].reshape(-1, 3).T).T + t[m]
            uv = (K[m] @ cam.T).T
            uv = (uv[:, :2] / uv[:, 2:]).reshape(2, 25, 2)
            order = rng.permutation(2)  # the candidates' order differs by view and frame
            orders.append(order)
            for j in range(25):
                xy = uv[order, j] / (np.array(SIZE) - 1)
                lines += [
                    "2",
                    " ".join(map(str, xy[:, 0].tolist())),
                    " ".join(map(str, xy[:, 1].tolist())),
                    "0.9 0.8",
                ]
            for _a, _b in shelf["PAF_PAIRS"]:
                same = np.equal.outer(order, order)
                lines += [" ".join("0.85" if s else "0.05" for s in row) for row in same]
        order_by_view.append(orders)
        with open(os.path.join(folder, "detection", f"{m}.txt"), "w") as f:
            f.write("\n".join(lines) + "\n")
    shelf_joints = [[score["shelf_from_body25"](p) for p in frame] for frame in people]
    lines = [f"15\t{frames}"]
    for frame in shelf_joints:
        lines.append("2")
        for pid, joints in enumerate(frame):
            lines.append(str(pid))
            block = np.vstack([joints.T, np.ones(15)])
            lines += [" ".join(map(str, row.tolist())) for row in block]
    with open(os.path.join(folder, "gt.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")
    return people, order_by_view, (K, R, t)


@pytest.fixture(scope="module")
def standin(tmp_path_factory):
    folder = str(tmp_path_factory.mktemp("shelf"))
    people, orders, cams = _write_standin(folder)
    return folder, people, orders, cams


def test_readers_give_back_what_was_written(standin):
    folder, people, orders, (K, R, t) = standin
    names, K2, R2, t2, size = shelf["read_calibration"](os.path.join(folder, "calibration.json"))
    assert names == ["0", "1", "2", "3", "4"] and size == SIZE
    np.testing.assert_allclose(K2, K)
    np.testing.assert_allclose(R2, R)
    np.testing.assert_allclose(t2, t)
    frames = shelf["read_candidates"](os.path.join(folder, "detection", "0.txt"), size)
    assert len(frames) == 3 and len(frames[0].joints) == 25 and len(frames[0].pafs) == 26
    cam = (R[0] @ people[0, orders[0][0][0], 1]) + t[0]
    uv = (K[0] @ cam)[:2] / (K[0] @ cam)[2]
    np.testing.assert_allclose(frames[0].joints[1][0, :2], uv, atol=1e-6)  # pixels again
    gt = shelf["read_skeletons"](os.path.join(folder, "gt.txt"))
    assert len(gt) == 3 and sorted(gt[0]) == [0, 1] and gt[0][0].shape == (15, 3)


def test_people_are_parsed_from_the_paf_scores(standin):
    folder, people, orders, _ = standin
    frames = shelf["read_candidates"](os.path.join(folder, "detection", "2.txt"), SIZE)
    for _f, frame in enumerate(frames):
        parsed = shelf["parse_people"](frame)
        assert len(parsed) == 2
        # each parsed person holds one candidate index for every joint: the same person's
        got = sorted(tuple(p) for p in parsed)
        assert got == [(0,) * 25, (1,) * 25]


def test_partial_people_merge_and_small_ones_are_dropped():
    """No neck: the limbs build a shoulder–elbow person and, apart, a nose–eye–ear person;
    the shoulder–ear limb (late in OpenPose's order) merges them. A lone ankle–toe pair of
    another person is too small to keep."""
    joints = [np.zeros((0, 3)) for _ in range(25)]
    for j in (2, 3, 0, 15, 17):
        joints[j] = np.array([[10.0 * j, 5.0, 0.9]])
    joints[14] = np.array([[1.0, 1.0, 0.9]])
    joints[19] = np.array([[2.0, 2.0, 0.9]])
    pafs = [np.full((len(joints[a]), len(joints[b])), 0.7) for a, b in shelf["PAF_PAIRS"]]
    parsed = shelf["parse_people"](shelf["Frame"](joints, pafs))
    assert len(parsed) == 1
    assert sorted(np.flatnonzero(parsed[0] >= 0)) == [0, 2, 3, 15, 17]


def test_the_command_runs_as_a_user_runs_it(standin, tmp_path):
    folder, people, _, _ = standin
    work = str(tmp_path / "work")
    report = shelf["main"](
        [folder, "--work", work, "--split", "all", "--json", str(tmp_path / "s.json")]
    )
    assert sorted(os.listdir(os.path.join(work, "pose"))) == ["0", "1", "2", "3", "4"]
    with open(os.path.join(work, "pose", "0", "000001_keypoints.json")) as f:
        assert len(json.load(f)["people"]) == 2
    assert report["frames"] == 3 and report["recall_10cm"] == 1.0
    assert (
        report["pcp_mean"] == 100.0 and report["mpjpe_mm"] < 5.0
    )  # the people of the command's output
    with open(tmp_path / "s.json") as f:
        assert json.load(f)["recall_10cm"] == 1.0


def test_splits_alternate_blocks_of_25():
    dev, held = shelf["split_frames"](301, "dev"), shelf["split_frames"](301, "held-out")
    assert list(dev[:26]) == list(range(25)) + [50] and list(held[:2]) == [25, 26]
    assert len(dev) + len(held) == 301 and held[-1] == 300 and not set(dev) & set(held)


def _truth():
    return score["shelf_from_body25"](TEMPLATE)


def test_pcp_counts_each_part_by_half_its_length():
    true = _truth()
    gt = [{0: true, 1: true + (2, 0, 0)}]
    perfect = score["pcp"]([[true, true + (2, 0, 0)]], gt, [0])
    assert perfect["pcp"] == {"actor 1": 100.0, "actor 2": 100.0} and perfect["mpjpe_mm"] == 0.0
    wrist = true.copy()
    length = np.linalg.norm(true[7] - true[6])  # right lower arm: elbow 7, wrist 6
    wrist[6] += (1.02 * length, 0, 0)  # mean end error 0.51 · length: wrong
    parts = score["correct_parts"](wrist, true)
    names = [name for name, _, _ in score["PARTS"]]
    assert list(np.flatnonzero(~parts)) == [names.index("right lower arm")]
    wrist[6] = true[6] + (0.98 * length, 0, 0)  # 0.49 · length: right
    assert score["correct_parts"](wrist, true).all()
    missing = true.copy()
    missing[13] = np.nan  # no head top: the head is wrong, the rest is scored
    assert list(np.flatnonzero(~score["correct_parts"](missing, true))) == [names.index("head")]


def test_pcp_matches_each_actor_to_its_nearest_person_and_scores_misses():
    true = _truth()
    gt = [{0: true, 1: true + (2, 0, 0)}, {0: true}]
    far = true + (0.3, 0, 0)
    out = score["pcp"]([[far, true + (2, 0, 0), true], []], gt, [0, 1])
    assert out["pcp"] == {"actor 1": 50.0, "actor 2": 100.0}  # frame 1: no one predicted
    assert out["scored"] == 3


def test_the_head_follows_the_4d_association_rule():
    """Neck half-way from the shoulders' centre to the ears' centre; head top 0.125 m along
    the face normal and 0.145 m up (the 4D-association repository's evaluation)."""
    body = TEMPLATE
    shelf15 = score["shelf_from_body25"](body)
    shoulders = (body[2] + body[5]) / 2
    ears = (body[17] + body[18]) / 2
    np.testing.assert_allclose(shelf15[12], shoulders + 0.5 * (ears - shoulders))
    face = np.cross(body[1] - body[8], body[2] - body[5])
    np.testing.assert_allclose(
        shelf15[13], shelf15[12] + 0.125 * face / np.linalg.norm(face) + (0, 0, 0.145)
    )
    assert np.allclose(face / np.linalg.norm(face), (0, -1, 0))  # it faces -y
    skel19 = body[list(score["BODY25_OF_SKEL19"])]
    body_again = score["body25_from_skel19"](skel19)
    np.testing.assert_allclose(score["shelf_from_body25"](body_again), shelf15)


def test_joint_recall_counts_points_of_the_joint_type_within_10_cm():
    true = _truth()
    gt = [{0: true}]
    points = [
        {
            score["BODY25_OF_SHELF"][s]: true[s][None] + (0.09 if s < 6 else 0.11, 0, 0)
            for s in range(12)
        }
    ]
    assert score["joint_recall"](points, gt, [0]) == 0.5


def test_openpose_folders_to_skeletons_in_one_command(standin, tmp_path):
    """``cdog-jax associate --points pose/ --keypoints BODY_25 --out people.trc``: one .trc
    file per person, BODY_25 names as markers; the JSON and CSV carry every group's person."""
    import subprocess
    import sys

    from cdog_jax.io import load_trc

    folder, people, _, _ = standin
    ready = shelf["prepare"](folder, str(tmp_path / "work"))
    base = [
        sys.executable,
        "-m",
        "cdog_jax",
        "associate",
        "--rig",
        ready["rig"],
        "--points",
        ready["pose"],
        "--keypoints",
        "BODY_25",
    ]
    done = subprocess.run(
        base + ["--out", str(tmp_path / "people.trc"), "--fps", "25", "--z-up"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert (
        "people: 2 id(s) over 3 frame(s), at most 2 per frame" in done.stdout
        and "warning" not in done.stdout
    )
    files = sorted(p.name for p in tmp_path.glob("people_person*.trc"))
    assert files == ["people_person0.trc", "people_person1.trc"]
    truth = people[..., [1, 2, 0]]  # z up written as y up
    for name in files:
        trc = load_trc(tmp_path / name)
        assert (
            trc.names[:3] == ("Nose", "Neck", "RShoulder")
            and len(trc.names) == 25
            and trc.rate == 25
        )
        assert trc.markers.shape == (3, 25, 3)
        # the same true person in every frame (ids kept), within 1 cm
        err = [
            [np.nanmean(np.linalg.norm(trc.markers[f] - truth[f, k], axis=-1)) for k in range(2)]
            for f in range(3)
        ]
        k = int(np.argmin(err[0]))
        assert all(np.argmin(e) == k and min(e) < 0.01 for e in err)
    # The other formats in this process (the child above ran the command as a user does).
    from cdog_jax.cli import main

    assert main(base[3:] + ["--out", str(tmp_path / "r.json")]) == 0
    with open(tmp_path / "r.json") as f:
        frames = json.load(f)["frames"]
    assert all(sorted({g["person"] for g in fr["groups"]}) == [0, 1] for fr in frames)
    assert [p["person"] for p in frames[0]["people"]] == [0, 1] and not any(
        g["mixed"] for g in frames[0]["groups"]
    )
    assert main(base[3:] + ["--out", str(tmp_path / "r.csv")]) == 0
    header = (tmp_path / "r.csv").read_text().splitlines()[1].split(",")
    assert header[-1] == "person"


def test_the_table_of_settings(standin, tmp_path):
    """experiments/real/shelf_table.py: each setting's command run and scored (one run each
    here), the table in markdown."""
    folder, *_ = standin
    table = runpy.run_path(os.path.join(REAL, "shelf_table.py"), run_name="shelf_table")
    rows = table["main"](
        [
            folder,
            "--work",
            str(tmp_path / "w"),
            "--split",
            "all",
            "--runs",
            "1",
            "--settings",
            "defaults,--sigma held",
            "--markdown",
            str(tmp_path / "t.md"),
        ]
    )
    assert len(rows) == 2 and rows[0]["setting"] == "defaults"  # no skel.txt: no 4D row
    # The held σ: the one σ fitted on every frame's detections, given to the command.
    held = rows[1]["setting"].split()
    assert held[:1] == ["--sigma"] and 0.0 < float(held[1]) < 50.0, rows[1]["setting"]
    assert all(r["pcp_mean"] == 100.0 and r["recall_10cm"] == 1.0 for r in rows)
    text = (tmp_path / "t.md").read_text().splitlines()
    assert text[0].startswith("| setting (all frames of 3)") and text[2].startswith(
        "| defaults | 100.0 / 100.0 /"
    )
    with pytest.raises(SystemExit):
        table["main"]([folder, "--settings", "no such"])


def test_the_stage_ablation(standin, tmp_path):
    """experiments/real/shelf_ablation.py: best() and best() without a stage, each through
    the command on the stand-in (scored) and on a small synthetic grid, in one table."""
    folder, *_ = standin
    ablation = runpy.run_path(os.path.join(REAL, "shelf_ablation.py"), run_name="shelf_ablation")
    rows = ablation["main"](
        [
            folder,
            "--work",
            str(tmp_path / "w"),
            "--variants",
            "best(),− IQR",
            "--sigmas",
            "1",
            "--counts",
            "5",
            "--out",
            str(tmp_path / "rows.json"),
        ]
    )
    assert [r["variant"] for r in rows["real"]] == ["best()", "− IQR"]
    assert all(r["pcp_mean"] == 100.0 and r["recall_10cm"] == 1.0 for r in rows["real"])
    assert [r["variant"] for r in rows["synthetic"]] == ["best()", "− IQR"]
    assert 0.5 < rows["synthetic"][0]["synthetic"]["1"]["pg_f1"] <= 1.0
    assert json.loads((tmp_path / "rows.json").read_text()) == rows
    with pytest.raises(SystemExit):
        ablation["main"]([folder, "--variants", "no such"])


def test_the_per_joint_rows(standin, tmp_path):
    """experiments/real/shelf_per_joint.py: every (frame, joint type) a scene of its own,
    with one rule changed per row, scored by recall on the dev frames."""
    folder, *_ = standin
    per_joint = runpy.run_path(os.path.join(REAL, "shelf_per_joint.py"), run_name="per_joint")
    names = ["best()", "best() σ = 4 px", "best() σ pooled per frame"]
    rows = per_joint["main"](
        [
            folder,
            "--work",
            str(tmp_path / "w"),
            "--rows",
            ",".join(names),
            "--out",
            str(tmp_path / "r.json"),
        ]
    )
    assert [r["row"] for r in rows] == names
    assert all(r["recall_10cm"] == 1.0 for r in rows), rows
    assert json.loads((tmp_path / "r.json").read_text()) == rows
    with pytest.raises(SystemExit):
        per_joint["main"]([folder, "--rows", "no such"])


def test_the_live_benchmark_reads_shelf_as_a_user_has_it(standin):
    """experiments/bench_live.py --shelf: the rig and the OpenPose frames, each detection with
    its joint class and its view's person, as load_rig and load_openpose give them."""
    folder, people, orders, (K, R, t) = standin
    bench = runpy.run_path(os.path.join(HERE, "..", "experiments", "bench_live.py"))
    rig, frames = bench["shelf_frames"](folder)
    np.testing.assert_allclose(np.asarray(rig.K), K, rtol=1e-6)
    assert len(frames) == 3
    for xy, mask, classes, instances in frames:
        assert xy.shape[:3] == mask.shape == classes.shape == instances.shape
        assert xy.shape[:2] == (1, 5) and xy.dtype == np.float32
        # two people, every BODY_25 joint of each in every view
        counts = np.stack([np.bincount(classes[0, m][mask[0, m]], minlength=25) for m in range(5)])
        assert (counts == 2).all()
        assert sorted(set(instances[mask].tolist())) == [0, 1]
        assert not np.isnan(xy).any()

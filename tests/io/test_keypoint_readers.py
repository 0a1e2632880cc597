"""Keypoint readers on tiny hand-written files: OpenPose camera folders, tables (CSV/NPZ),
detections JSON with classes; the keypoint score rule."""

import json
import os

import numpy as np
import pytest

from cdog_jax.io import InputError, load_detections, load_keypoint_table, load_openpose
from cdog_jax.io._scores import normalise_keypoint_scores


def _person(points):
    """``[(x, y, score), …]`` as OpenPose's flat ``pose_keypoints_2d``."""
    return {"person_id": [-1], "pose_keypoints_2d": [v for p in points for v in p]}


def _write_openpose(folder, cameras):
    """``cameras``: {camera folder name: {file name: [person points, …]}}."""
    for cam, files in cameras.items():
        os.makedirs(os.path.join(folder, cam))
        for name, people in files.items():
            with open(os.path.join(folder, cam, name), "w") as f:
                json.dump({"version": 1.3, "people": [_person(p) for p in people]}, f)
    return str(folder)


A = [(10.0, 20.0, 0.9), (30.0, 40.0, 0.0), (50.0, 60.0, 0.8)]  # keypoint 1 not detected
B = [(11.0, 21.0, 0.7), (31.0, 41.0, 0.6), (51.0, 61.0, 0.5)]


def test_openpose_folders_slots_classes_frames(tmp_path):
    # cam10 sorts after cam2 (natural order); frame 7 exists only in cam2; frame numbers from names.
    folder = _write_openpose(
        tmp_path,
        {
            "cam2_json": {
                "v_000000000005_keypoints.json": [A, B],
                "v_000000000007_keypoints.json": [B],
            },
            "cam10_json": {"v_000000000005_keypoints.json": [B, A]},
        },
    )
    det = load_openpose(folder, keypoints=["nose", "neck", "hip"])
    assert det.xy.shape == (2, 2, 6, 2) and det.frames
    assert det.frame_ids.tolist() == [5, 7]
    assert det.class_names == ("nose", "neck", "hip")
    # slot = person · J + j; class = j; score 0 is missing, scores kept.
    assert det.classes[0, 0].tolist() == [0, -1, 2, 0, 1, 2]
    assert det.mask[0, 0].tolist() == [True, False, True, True, True, True]
    np.testing.assert_allclose(det.xy[0, 0, 5], [51.0, 61.0])
    np.testing.assert_allclose(det.confidence[0, 0], [0.9, 0.0, 0.8, 0.7, 0.6, 0.5])
    assert det.classes[0, 1].tolist() == [0, 1, 2, 0, -1, 2]  # cam10 is view 1
    assert not det.mask[1, 1].any()  # frame 7 missing in cam10: an empty view
    assert det.mask[1, 0, :3].all() and not det.mask[1, 0, 3:].any()
    assert any("frames numbered 5…7" in n for n in det.notes)


def test_openpose_skeleton_names_and_errors(tmp_path):
    folder = _write_openpose(tmp_path / "ok", {"a": {"f1.json": [A]}, "b": {"f1.json": [B]}})
    with pytest.raises(InputError, match="3 keypoints per person; keypoints='COCO_17' names 17"):
        load_openpose(folder, keypoints="COCO_17")
    with pytest.raises(InputError, match="2 camera folders; the rig has 3 views"):
        load_openpose(folder, num_views=3)
    bad = _write_openpose(tmp_path / "bad", {"a": {"f1.json": [A]}, "b": {"f1.json": [A, A[:2]]}})
    with pytest.raises(InputError, match=r"f1\.json: person 1: 2 keypoints; .* has 3"):
        load_openpose(bad)
    neg = _write_openpose(
        tmp_path / "neg", {"a": {"f1.json": [A]}, "b": {"f1.json": [[(1.0, 2.0, -0.5)] * 3]}}
    )
    with pytest.raises(InputError, match="score -0.5 is negative"):
        load_openpose(neg)
    nonum = _write_openpose(tmp_path / "nonum", {"a": {"x.json": [A]}, "b": {"x.json": [B]}})
    with pytest.raises(InputError, match="no frame number in the file name"):
        load_openpose(nonum)


def test_openpose_two_people_of_one_class_at_one_pixel_refused_but_classes_may_coincide(tmp_path):
    same = [
        (10.0, 20.0, 0.9),
        (10.0, 20.0, 0.9),
        (50.0, 60.0, 0.8),
    ]  # keypoints 0 and 1 coincide: fine
    det = load_openpose(
        _write_openpose(tmp_path / "ok", {"a": {"f1.json": [same]}, "b": {"f1.json": [B]}})
    )
    assert det.mask[0, 0].sum() == 3
    dup = _write_openpose(tmp_path / "dup", {"a": {"f1.json": [A, A]}, "b": {"f1.json": [B]}})
    with pytest.raises(InputError, match="duplicates"):
        load_openpose(dup)


def test_keypoint_score_rule():
    mask = np.ones((1, 1, 3), bool)
    err = lambda text, *loc: ValueError(text)  # noqa: E731
    conf, note = normalise_keypoint_scores(np.array([[[0.5, 1.04, 0.2]]]), mask, err)
    np.testing.assert_allclose(conf, [[[0.5, 1.0, 0.2]]])  # probabilities: clipped at 1
    assert "clipped" in note
    conf, note = normalise_keypoint_scores(np.array([[[2.0, 8.0, 4.0]]]), mask, err)
    np.testing.assert_allclose(conf, [[[0.25, 1.0, 0.5]]])  # another scale: divided by the largest
    assert "divided by the largest" in note
    with pytest.raises(ValueError, match="negative, infinite or NaN"):
        normalise_keypoint_scores(np.array([[[0.5, np.inf, 0.2]]]), mask, err)


def test_table_csv_names_and_npz_ids(tmp_path):
    csv_path = tmp_path / "t.csv"
    csv_path.write_text(
        "# comment\nframe,view,class,x,y,score\n"
        "3,0,nose,1,2,0.9\n3,1,nose,3,4,1.0\n3,0,neck,1,2,0.8\n3,0,nose,5,6,0\n9,1,neck,7,8,12\n"
    )
    det = load_keypoint_table(csv_path)
    assert det.class_names == ("nose", "neck") and det.frame_ids.tolist() == [3, 9]
    assert det.xy.shape == (2, 2, 3, 2)
    assert det.classes[0, 0].tolist() == [0, 1, -1]  # the nose row of score 0 is no detection
    assert det.mask[0, 0].tolist() == [True, True, False]
    np.testing.assert_allclose(
        det.confidence[0, 0, :2], [0.9 / 12, 0.8 / 12]
    )  # largest 12 > 1.1: divided
    assert det.classes[1, 1, 0] == 1
    npz_path = tmp_path / "t.npz"
    np.savez(
        npz_path,
        frame=[0, 0, 0],
        view=[0, 1, 1],
        **{"class": [2, 2, 0]},
        xy=[[1, 2], [3, 4], [3, 4]],
    )
    det = load_keypoint_table(npz_path, num_views=3)
    assert (
        det.class_names is None
        and det.classes[0, 1].tolist() == [2, 0]
        and det.mask.shape == (1, 3, 2)
    )
    assert det.confidence is not None and (det.confidence[det.mask] == 1.0).all()


def test_table_errors_name_the_row(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("frame,view,x,y\n0,0,1,2\n")
    with pytest.raises(InputError, match="lacks column"):
        load_keypoint_table(p)
    p.write_text("frame,view,class,x,y\n0,0,a,1,2\n0,5,a,1,2\n")
    with pytest.raises(InputError, match=r"line 3: view 5 must be in 0…1"):
        load_keypoint_table(p, num_views=2)
    p.write_text("frame,view,class,x,y\n0,0,a,1,2\n0,1,a,one,2\n")
    with pytest.raises(InputError, match=r"line 3: x 'one' is not a number"):
        load_keypoint_table(p)
    # Numbers no frame or view can have are refused before anything is allocated for them.
    p.write_text("frame,view,class,x,y\n100000000000000000000,0,a,1,2\n0,1,a,1,2\n")
    with pytest.raises(InputError, match=r"line 2: frame '1000.*' is out of range \(a 32-bit"):
        load_keypoint_table(p)
    p.write_text("frame,view,class,x,y\n0,0,a,1,2\n0,2000000000,a,1,2\n")
    with pytest.raises(InputError, match=r"line 3: view 2000000000 must be in 0…1023 \(without"):
        load_keypoint_table(p)
    np.savez(
        tmp_path / "t.npz",
        frame=np.array([0, 2**40]),
        view=np.array([0, 1]),
        **{"class": np.array([0, 0])},
        x=np.array([1.0, 2.0]),
        y=np.array([1.0, 2.0]),
    )
    with pytest.raises(InputError, match=r"frame 1099511627776 is out of range"):
        load_keypoint_table(tmp_path / "t.npz")


def test_readers_carry_the_per_view_instance(tmp_path):
    """OpenPose: the person's index in its view (people without keypoints skipped), also
    after packing to a capacity; tables: the optional instance column (-1 unknown)."""
    empty = {"person_id": [-1], "pose_keypoints_2d": []}
    folder = tmp_path / "op"
    _write_openpose(folder, {"a": {"f1.json": [A, B]}, "b": {"f1.json": [B]}})
    with open(folder / "b" / "f1.json", "w") as f:
        json.dump({"people": [empty, _person(B), _person(A)]}, f)
    det = load_openpose(str(folder))
    assert det.instances[0, 0].tolist() == [0, -1, 0, 1, 1, 1]  # A's keypoint 1 not detected
    assert det.instances[0, 1].tolist() == [0, 0, 0, 1, -1, 1]
    packed = load_openpose(str(folder), capacity=6)
    np.testing.assert_array_equal(packed.instances, det.instances)
    assert (
        load_keypoint_table(
            _csv(tmp_path, "frame,view,class,x,y\n0,0,a,1,2\n0,1,a,3,4\n")
        ).instances
        is None
    )
    p = _csv(
        tmp_path,
        "frame,view,class,x,y,score,instance\n0,0,a,1,2,1,3\n0,1,a,3,4,1,-1\n0,1,a,5,6,0,2\n0,0,b,1,2,1,0\n",
    )
    det = load_keypoint_table(p)
    assert det.instances[0].tolist() == [[3, 0], [-1, -1]]  # the score-0 row is no detection
    p.write_text("frame,view,class,x,y,instance\n0,0,a,1,2,-2\n")
    with pytest.raises(InputError, match="line 2: instance -2 must be >= -1"):
        load_keypoint_table(p)
    p.write_text("frame,view,class,x,y,instance\n0,0,a,1,2,x\n")
    with pytest.raises(InputError, match="line 2: instance 'x' is not an integer"):
        load_keypoint_table(p)


def _csv(tmp_path, text):
    p = tmp_path / "t.csv"
    p.write_text(text)
    return p


def test_detections_json_classes_per_detection_and_by_class(tmp_path):
    p = tmp_path / "d.json"
    p.write_text(
        json.dumps(
            {
                "class_names": ["a", "b"],
                "views": [[[1, 2], [1, 2]], [[3, 4]]],
                "classes": [["a", "b"], ["b"]],
            }
        )
    )
    det = load_detections(p)
    assert det.class_names == ("a", "b") and det.classes[0].tolist() == [[0, 1], [1, -1]]
    p.write_text(
        json.dumps({"frames": [{"by_class": {"x": [[[1, 2]], [[3, 4]]], "y": [[[5, 6]], []]}}]})
    )
    det = load_detections(p)
    assert det.class_names == ("x", "y") and det.classes[0].tolist() == [[0, 1], [0, -1]]
    np.testing.assert_allclose(det.xy[0, 0], [[1, 2], [5, 6]])
    p.write_text(json.dumps({"views": [[[1, 2], [1, 2]], [[3, 4]]], "classes": [[0, 0], [0]]}))
    with pytest.raises(InputError, match="duplicates"):  # one class, one pixel
        load_detections(p)
    p.write_text(json.dumps({"views": [[[1, 2]], [[3, 4]]], "classes": [[0], [0, 1]]}))
    with pytest.raises(
        InputError, match=r"view 1: \"classes\" must hold one class per detection \(1\); got 2"
    ):
        load_detections(p)
    p.write_text(json.dumps({"views": [[[1, 2]], [[3, 4]]], "classes": [[0], ["a"]]}))
    with pytest.raises(InputError, match="mixes class ids and class names"):
        load_detections(p)


def test_a_table_saved_with_a_byte_order_mark_reads(tmp_path):
    """A spreadsheet's "CSV UTF-8" starts with a byte-order mark; the header still reads."""
    text = "frame,view,class,x,y\n0,0,nose,1,2\n0,1,nose,3,4\n"
    plain, marked = tmp_path / "plain.csv", tmp_path / "marked.csv"
    plain.write_text(text, encoding="utf-8")
    marked.write_text(text, encoding="utf-8-sig")
    assert marked.read_bytes()[:3] == b"\xef\xbb\xbf"
    a, b = load_keypoint_table(plain), load_keypoint_table(marked)
    np.testing.assert_array_equal(a.xy, b.xy)
    assert a.class_names == b.class_names == ("nose",)


@pytest.mark.parametrize("scale", [1.0, 50.0], ids=["probabilities", "another-scale"])
def test_openpose_read_in_parts_as_the_whole(tmp_path, scale):
    """A long recording read a part at a time: every part what the whole read gives for its
    frames (slots as wide as the most people of any frame, scores by the whole's rule),
    the whole's notes; a bad file in a later part is refused when the reader is made,
    naming its frame as the whole does."""
    from cdog_jax.io._keypoints import OpenPoseParts

    rng = np.random.default_rng(0)
    cameras = {"cam0": {}, "cam1": {}, "cam2": {}}
    for f in range(7):
        for m, cam in enumerate(cameras):
            people = 1 + (f * 3 + m) % 3 if f != 4 else (1 if m == 0 else 0)  # frame 4: 1 view
            cameras[cam][f"{10 + 2 * f:06d}_keypoints.json"] = [
                [
                    (float(x), float(y), float(s) * scale)
                    for x, y, s in zip(*rng.uniform(0, 600, (2, 3)), rng.uniform(0.2, 1.05, 3))
                ]
                for _ in range(people)
            ]
    folder = _write_openpose(tmp_path / "pose", cameras)
    whole = load_openpose(folder)
    parts = OpenPoseParts(folder, part_frames=3)
    assert [(p.start, p.stop) for p in parts.parts] == [(0, 3), (3, 6), (6, 7)]
    read = [parts.read(k) for k in range(3)]
    for name in ("xy", "mask", "confidence", "classes", "instances", "counts", "frame_ids"):
        np.testing.assert_array_equal(
            np.concatenate([getattr(d, name) for d in read]), getattr(whole, name), err_msg=name
        )
    assert sorted(parts.notes) == sorted(whole.notes) and len(whole.notes) >= 3
    assert all(d.class_names == whole.class_names and d.frames for d in read)

    with open(os.path.join(folder, "cam1", "000022_keypoints.json"), "w") as f:  # frame 6
        json.dump({"people": [_person([(1.0, 2.0, -0.5)] * 3)]}, f)
    for read_it in (lambda: load_openpose(folder), lambda: OpenPoseParts(folder, part_frames=3)):
        with pytest.raises(InputError, match="frame 6, view 1, detection 0: score -0.5"):
            read_it()

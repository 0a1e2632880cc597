"""Files say what they mean, or are refused: a key or column the reader does not know (a
misspelt ``"distortion"``, ``"clases"``, a ``scores`` column) is an error naming the nearest
known one, and a key given twice in one JSON object (or a column twice in a table) is
refused rather than read last-wins."""

import json

import numpy as np
import pytest

from cdog_jax.io import load_detections, load_keypoint_table, load_rig, save_rig
from cdog_jax.synthetic import default_rig


@pytest.fixture
def rig_json(tmp_path):
    path = tmp_path / "rig.json"
    save_rig(path, default_rig(num_views=3), format="json", image_size=(640, 480))
    return path


def _refused(read, path, *expected):
    with pytest.raises(ValueError) as info:
        read(path)
    for text in expected:
        assert text in str(info.value), str(info.value)


def test_rig_json_keys(rig_json):
    data = json.loads(rig_json.read_text())
    data["views"][1]["distortion"] = [0.1, 0.0, 0.0, 0.0, 0.0]
    rig_json.write_text(json.dumps(data))
    _refused(load_rig, rig_json, "view 1", 'unknown key "distortion"', 'did you mean "dist"')
    data["views"][1].pop("distortion")
    data["views"][1]["fish_eye"] = [0.0] * 4
    rig_json.write_text(json.dumps(data))
    _refused(load_rig, rig_json, 'unknown key "fish_eye"', 'did you mean "fisheye"')
    data["views"][1].pop("fish_eye")
    data["camera"] = "x"
    rig_json.write_text(json.dumps(data))
    _refused(load_rig, rig_json, 'unknown key "camera"')
    data.pop("camera")
    text = json.dumps(data).replace('"t": [', '"t": [9, 9, 9], "t": [', 1)
    rig_json.write_text(text)
    _refused(load_rig, rig_json, 'the key "t" appears twice')
    rig_json.write_text(json.dumps(data))
    assert load_rig(rig_json).rig.num_views == 3


def test_detections_json_keys(tmp_path):
    path = tmp_path / "det.json"
    views = [[[1.0, 2.0]], [[3.0, 4.0]]]
    path.write_text(json.dumps({"views": views, "clases": [[0], [0]]}))
    _refused(load_detections, path, 'unknown key "clases"', 'did you mean "classes"')
    path.write_text(json.dumps({"frames": [{"views": views, "confidence": [[1], [1]]}]}))
    _refused(load_detections, path, "frame 0", 'unknown key "confidence"')
    path.write_text('{"views": [[[1, 2]], [[3, 4]]], "views": [[[5, 6]], [[7, 8]]]}')
    _refused(load_detections, path, 'the key "views" appears twice')
    path.write_text(json.dumps({"views": views, "classes": [[0], [1]], "class_names": ["a", "b"]}))
    assert load_detections(path).mask.sum() == 2


def test_table_columns(tmp_path):
    path = tmp_path / "points.csv"
    rows = "0,0,0,1,2,0.5\n0,1,0,3,4,0.5\n"
    path.write_text("frame,view,class,x,y,scores\n" + rows)
    _refused(load_keypoint_table, path, 'unknown column "scores"', 'did you mean "score"')
    path.write_text("frame,view,class,x,y,x\n" + rows)
    _refused(load_keypoint_table, path, 'the column "x" appears twice')
    path.write_text("\ufeffframe,view,class,x,y,score\n" + rows, encoding="utf-8")
    det = load_keypoint_table(path)  # a spreadsheet's byte-order mark is read past
    np.testing.assert_allclose(det.confidence[0][det.mask[0]], [0.5, 0.5])
    npz = tmp_path / "points.npz"
    columns = {"frame": [0, 0], "view": [0, 1], "class": [0, 0], "x": [1.0, 3.0], "y": [2.0, 4.0]}
    np.savez(npz, **{k: np.asarray(v) for k, v in columns.items()}, instanse=np.zeros(2, int))
    _refused(load_keypoint_table, npz, 'unknown array "instanse"', 'did you mean "instance"')


def test_two_cameras_with_one_name_are_refused(tmp_path):
    from cdog_jax.io import save_rig

    save_rig(tmp_path, default_rig(num_views=3), format="colmap", image_size=(640, 480))
    images = tmp_path / "images.txt"
    images.write_text(images.read_text().replace(" view_1\n", " view_0\n"))
    _refused(load_rig, images, "two cameras are named 'view_0'", "views 0 and 1")

"""Detection files and the encodings of "missing" (docs/CONVENTIONS.md §3): every encoding gives the same
dense (xy, mask), and every error names the file, frame, view and detection index."""

import json
import re

import numpy as np
import pytest

from cdog_jax.io._detections import (
    Detections,
    detections_from_array,
    detections_from_lists,
    load_detections,
)

NAN = float("nan")
# One scene, 3 views; view 1 has one detection missing in slot 0 (as the dense encodings
# write it) and view 2 has three detections.
XY = np.array(
    [
        [[10.0, 20.0], [30.0, 40.0], [0.0, 0.0]],
        [[0.0, 0.0], [50.0, 60.0], [0.0, 0.0]],
        [[70.0, 80.0], [90.0, 100.0], [110.0, 120.0]],
    ]
)
MASK = np.array([[True, True, False], [False, True, False], [True, True, True]])
CONF = np.where(MASK, 0.5, 0.0)


def _encoded(kind):
    """XY/MASK with the missing rows written in encoding ``kind``, shape (3, 3, 2|3)."""
    rows = XY.copy()
    if kind == "nan":
        rows[~MASK] = NAN
    elif kind == "sentinel":
        rows[~MASK] = -1.0
    elif kind == "confidence":
        rows = np.concatenate(
            [rows + 7.0 * ~MASK[..., None], CONF[..., None]], axis=-1
        )  # garbage coords
    return rows


def _write_json(tmp_path, data, name="det.json"):
    path = tmp_path / name
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def _scene_views():
    return [[[10, 20], [30, 40]], [[50, 60]], [[70, 80], [90, 100], [110, 120]]]


# Encodings -------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["nan", "sentinel", "confidence"])
@pytest.mark.parametrize("explicit", [False, True])
def test_missing_encodings_give_the_same_xy_and_mask(kind, explicit):
    det = detections_from_array(_encoded(kind), missing=kind if explicit else "auto")
    xy, mask, conf = det.scene(0)
    np.testing.assert_array_equal(mask, MASK)
    np.testing.assert_array_equal(xy, np.where(MASK[..., None], XY, 0.0))
    assert det.frames is False and det.xy.shape == (1, 3, 3, 2)
    np.testing.assert_array_equal(det.counts, [[2, 1, 3]])
    if kind == "confidence":
        np.testing.assert_array_equal(conf, CONF)
    else:
        assert conf is None
    if not explicit:
        assert any(
            "missing='auto'" in n
            and {"nan": "NaN", "sentinel": "sentinel", "confidence": "confidence 0"}[kind] in n
            for n in det.notes
        )


def test_sentinel_is_a_detection_under_nan_encoding():
    rows = _encoded("nan")
    rows[0, 2] = -1.0
    det = detections_from_array(rows, missing="nan")
    np.testing.assert_array_equal(det.mask[0, 0], [True, True, True])
    assert det.mask.sum() == MASK.sum() + 1


def test_ragged_lists_and_mask_npz_match_the_array_encodings(tmp_path):
    # The lists hold view 1's detection in slot 0; a NaN placeholder keeps its array slot.
    det = detections_from_lists(
        [[[10, 20], [30, 40]], [[NAN, NAN], [50, 60]], [[70, 80], [90, 100], [110, 120]]]
    )
    np.testing.assert_array_equal(det.mask[0], MASK)
    np.testing.assert_array_equal(det.xy[0], np.where(MASK[..., None], XY, 0.0))
    path = tmp_path / "det.npz"
    np.savez(path, xy=XY, mask=MASK)
    from_npz = load_detections(path)
    np.testing.assert_array_equal(from_npz.xy, det.xy)
    np.testing.assert_array_equal(from_npz.mask, det.mask)


def test_ragged_lists_grow_to_the_fullest_view():
    det = detections_from_lists(_scene_views())
    assert det.xy.shape == (1, 3, 3, 2)
    np.testing.assert_array_equal(det.counts, [[2, 1, 3]])
    np.testing.assert_array_equal(det.mask[0, 1], [True, False, False])
    np.testing.assert_array_equal(det.xy[0, 2, 2], [110, 120])


def test_confidence_entries():
    det = detections_from_lists([[[1, 2, 0.9]], [[3, 4, 0.25], [5, 6, 1]]])
    np.testing.assert_array_equal(det.confidence[0], [[0.9, 0.0], [0.25, 1.0]])
    # With missing="nan" a confidence of 0 is a detection, not a missing row.
    det = detections_from_lists([[[1, 2, 0.0]], [[3, 4, 0.5]]], missing="nan")
    assert det.mask.sum() == 2


def test_json_frames(tmp_path):
    frames = [
        {"views": _scene_views()},
        {"views": [[[1, 2]], [], [[3, 4], [5, 6], [7, 8], [9, 10]]]},
    ]
    det = load_detections(_write_json(tmp_path, {"frames": frames}), num_views=3)
    assert det.frames is True
    assert det.xy.shape == (2, 3, 4, 2)
    np.testing.assert_array_equal(det.counts, [[2, 1, 3], [1, 0, 4]])
    assert det.notes == ["frame 1, view 1: empty view"]
    xy, mask, conf = det.scene(1)
    np.testing.assert_array_equal(xy[2, 3], [9, 10])
    assert mask.shape == (3, 4) and conf is None


def test_json_one_scene_and_empty_view_note(tmp_path):
    det = load_detections(_write_json(tmp_path, {"views": [[[1, 2]], [], [[3, 4]]]}))
    assert det.frames is False and det.xy.shape == (1, 3, 1, 2)
    assert det.notes == ["view 1: empty view"]


@pytest.mark.parametrize("frame_axis", [False, True])
@pytest.mark.parametrize("with_mask", [False, True])
def test_npz_with_and_without_frame_axis_and_mask(tmp_path, frame_axis, with_mask):
    arrays = {"xy": XY, "mask": MASK, "confidence": CONF} if with_mask else {"xy": _encoded("nan")}
    if frame_axis:
        arrays = {k: np.stack([v, v]) for k, v in arrays.items()}
    path = tmp_path / "det.npz"
    np.savez(path, **arrays)
    det = load_detections(path)
    F = 2 if frame_axis else 1
    assert det.frames is frame_axis
    assert det.xy.shape == (F, 3, 3, 2)
    np.testing.assert_array_equal(det.mask, np.broadcast_to(MASK, (F, 3, 3)))
    np.testing.assert_array_equal(
        det.xy, np.broadcast_to(np.where(MASK[..., None], XY, 0.0), (F, 3, 3, 2))
    )
    assert (det.confidence is not None) is with_mask


def test_capacity_grows():
    det = detections_from_lists(_scene_views(), capacity=5)
    assert det.xy.shape == (1, 3, 5, 2)
    assert det.mask[0, :, 3:].sum() == 0


def test_capacity_packs_views_and_says_so():
    # View 1 holds one detection in slot 1; capacity 1 moves it to slot 0.
    rows = np.array([[[1.0, 2.0], [NAN, NAN]], [[NAN, NAN], [50.0, 60.0]]])
    det = detections_from_array(rows, capacity=1)
    np.testing.assert_array_equal(det.mask[0], [[True], [True]])
    np.testing.assert_array_equal(det.xy[0, 1, 0], [50, 60])
    assert any("view 1: detections moved to slots 0…0 to fit capacity 1" in n for n in det.notes)


# Errors ----------------------------------------------------------------------------------


def test_capacity_refuses_to_truncate(tmp_path):
    frames = [{"views": [[[1, 2]], [[3, 4]]]}, {"views": [[[1, 2], [5, 6], [7, 8]], [[3, 4]]]}]
    path = _write_json(tmp_path, {"frames": frames})
    with pytest.raises(
        ValueError,
        match=re.escape(f"{path}: frame 1, view 0: 3 detections exceed the capacity of 2"),
    ):
        load_detections(path, capacity=2)


def test_a_capacity_beyond_the_machine_is_refused_before_padding(tmp_path, monkeypatch):
    import cdog_jax._runtime.memory as memory

    monkeypatch.setattr(memory, "physical_memory", lambda: 10**6)  # a 1 MB machine
    path = _write_json(tmp_path, {"frames": [{"views": [[[1, 2]], [[3, 4]]]}] * 2})
    assert load_detections(path, capacity=1000).mask.shape == (2, 2, 1000)  # 68 kB: padded
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{path}: capacity 100000: padding 2 frame(s) × 2 view(s) to 100000 slots takes "
            "6.8 MB, more than half of this machine's 1.0 MB; the fullest view holds 1 detections"
        ),
    ):
        load_detections(path, capacity=100_000)


def test_non_numeric_entry(tmp_path):
    path = _write_json(tmp_path, {"views": [[[1, 2]], [[3, 4], [5, "x"]]]})
    with pytest.raises(
        ValueError, match=re.escape(f"{path}: view 1, detection 1: non-numeric entry [5, 'x']")
    ):
        load_detections(path)


def test_non_numeric_entry_in_frames(tmp_path):
    frames = [{"views": [[[1, 2]], [[3, 4]]]}, {"views": [[[1, None]], [[3, 4]]]}]
    path = _write_json(tmp_path, {"frames": frames})
    with pytest.raises(
        ValueError, match=re.escape(f"{path}: frame 1, view 0, detection 0: non-numeric entry")
    ):
        load_detections(path)


def test_non_numeric_npz(tmp_path):
    path = tmp_path / "det.npz"
    np.savez(path, xy=np.array([[["a", "b"]], [["c", "d"]]]))
    with pytest.raises(ValueError, match=re.escape(f'{path}: array "xy": non-numeric entries')):
        load_detections(path)


@pytest.mark.parametrize("entry", [[1], [1, 2, 0.5, 4]])
def test_wrong_entry_length(tmp_path, entry):
    path = _write_json(tmp_path, {"views": [[[1, 2]], [[3, 4], entry]]})
    with pytest.raises(
        ValueError,
        match=re.escape(f"{path}: view 1, detection 1: entry {entry!r} has {len(entry)} numbers"),
    ):
        load_detections(path)


def test_mixed_entry_lengths(tmp_path):
    path = _write_json(tmp_path, {"views": [[[1, 2, 0.5]], [[3, 4]]]})
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{path}: view 1, detection 0: entry has 2 numbers but view 0, detection 0 has 3"
        ),
    ):
        load_detections(path)


@pytest.mark.parametrize(
    ("row", "text"),
    [
        ([1.0, NAN], "one NaN coordinate and one finite"),
        ([float("inf"), 2.0], "an infinite coordinate"),
    ],
)
def test_malformed_rows_are_not_missing(tmp_path, row, text):
    rows = _encoded("nan")
    rows[2, 1] = row
    with pytest.raises(
        ValueError, match=re.escape(f"view 2, detection 1: ({row[0]}, {row[1]}) has {text}")
    ):
        detections_from_array(rows)
    path = tmp_path / "det.npz"
    np.savez(path, xy=np.stack([rows, rows]))
    with pytest.raises(ValueError, match=re.escape(f"{path}: frame 0, view 2, detection 1: ")):
        load_detections(path)


def test_nan_in_json_entry(tmp_path):
    path = _write_json(tmp_path, {"views": [[[1, 2]], [[NAN, 4]]]})
    with pytest.raises(
        ValueError,
        match=re.escape(f"{path}: view 1, detection 0: (nan, 4.0) has one NaN coordinate"),
    ):
        load_detections(path)


def test_nan_where_it_does_not_mean_missing(tmp_path):
    with pytest.raises(
        ValueError,
        match=re.escape(
            "view 0, detection 2: (nan, nan) has NaN coordinates where they do not mean missing (missing='sentinel')"
        ),
    ):
        detections_from_array(_encoded("nan"), missing="sentinel")
    xy = XY.copy()
    xy[0, 1] = NAN
    path = tmp_path / "det.npz"
    np.savez(path, xy=xy, mask=MASK)
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{path}: view 0, detection 1: (nan, nan) has NaN coordinates where mask is True"
        ),
    ):
        load_detections(path)


def test_duplicates_name_both_indices(tmp_path):
    frames = [{"views": _scene_views()}, {"views": [[[1, 2]], [[3, 4]], [[5, 6], [7, 8], [5, 6]]]}]
    path = _write_json(tmp_path, {"frames": frames})
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{path}: frame 1, view 2: detections 0 and 2 are duplicates (both at (5.0, 6.0))"
        ),
    ):
        load_detections(path)


def test_far_outside_the_image(tmp_path):
    path = _write_json(tmp_path, {"views": [[[1, 2]], [[3, 4], [1000, -300]]]})
    load_detections(path, image_size=(1000, 1000))  # inside the margin: fine
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{path}: view 1, detection 1: (1000, -300) lies 360 px right of and 300 px above the 640×480 image"
        ),
    ):
        load_detections(path, image_size=(640, 480))


def test_view_count_differs_from_the_rig(tmp_path):
    path = _write_json(tmp_path, {"views": _scene_views()})
    with pytest.raises(ValueError, match=re.escape(f"{path}: 3 views; the rig has 4 (num_views)")):
        load_detections(path, num_views=4)
    path = tmp_path / "det.npz"
    np.savez(path, xy=XY, mask=MASK)
    with pytest.raises(ValueError, match=re.escape(f"{path}: 3 views; the rig has 2")):
        load_detections(path, num_views=2)


def test_view_count_differs_between_frames(tmp_path):
    frames = [{"views": _scene_views()}, {"views": _scene_views()[:2]}]
    path = _write_json(tmp_path, {"frames": frames})
    with pytest.raises(ValueError, match=re.escape(f"{path}: frame 1: 2 views; frame 0 has 3")):
        load_detections(path)


def test_no_views(tmp_path):
    path = _write_json(tmp_path, {"views": []})
    with pytest.raises(ValueError, match=re.escape(f"{path}: no views")):
        load_detections(path)


def test_fewer_than_two_views_with_detections(tmp_path):
    frames = [{"views": _scene_views()}, {"views": [[], [[1, 2]], []]}]
    path = _write_json(tmp_path, {"frames": frames})
    det = load_detections(path)  # frame 1 cannot give a group: kept, with a note
    assert "frame 1 (1 of 2): fewer than 2 views with detections; they get zero groups" in det.notes
    path = _write_json(tmp_path, {"views": [[], [[1, 2]], []]})
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{path}: 1 view(s) with detections (view 1); association needs at least 2"
        ),
    ):
        load_detections(path)


@pytest.mark.parametrize("c", [1.5, -0.25, NAN])
def test_confidence_outside_unit_interval(tmp_path, c):
    path = _write_json(tmp_path, {"views": [[[1, 2, 0.5]], [[3, 4, 0.5], [5, 6, c]]]})
    with pytest.raises(
        ValueError,
        match=re.escape(f"{path}: view 1, detection 1: confidence {c} is outside [0, 1] or NaN"),
    ):
        load_detections(path)
    path = tmp_path / "det.npz"
    conf = CONF.copy()
    conf[2, 2] = c
    np.savez(path, xy=XY, mask=MASK, confidence=conf)
    with pytest.raises(ValueError, match=re.escape(f"{path}: view 2, detection 2: confidence {c}")):
        load_detections(path)


def test_bad_files_and_options(tmp_path):
    path = tmp_path / "det.json"
    path.write_text("{not json", encoding="utf-8")
    with pytest.raises(ValueError, match=re.escape(f"{path}: not valid JSON")):
        load_detections(path)
    path = _write_json(tmp_path, {"detections": []})
    with pytest.raises(ValueError, match=re.escape(f'{path}: expected {{"views"')):
        load_detections(path)
    path = tmp_path / "det.npz"
    np.savez(path, xy=XY, mask=MASK[:, :2])
    with pytest.raises(ValueError, match=re.escape(f'{path}: array "mask": expected shape (3, 3)')):
        load_detections(path)
    with pytest.raises(ValueError, match=re.escape("image_size must be (width, height)")):
        detections_from_lists(_scene_views(), image_size=(640, -480))
    with pytest.raises(ValueError, match="missing must be one of"):
        detections_from_lists(_scene_views(), missing="zero")
    with pytest.raises(
        ValueError, match=re.escape("missing='confidence' needs a confidence column")
    ):
        detections_from_array(XY, missing="confidence")
    with pytest.raises(
        ValueError, match=re.escape(f"{tmp_path / 'det.txt'}: cannot tell the detections format")
    ):
        load_detections(tmp_path / "det.txt")


def test_result_type():
    det = detections_from_lists(_scene_views())
    assert isinstance(det, Detections)
    assert (
        det.xy.dtype == np.float64 and det.mask.dtype == np.bool_ and det.counts.dtype == np.int64
    )


def test_json_with_a_byte_order_mark_reads(tmp_path):
    path = tmp_path / "bom.json"
    path.write_text(json.dumps({"views": _scene_views()}), encoding="utf-8-sig")
    assert load_detections(str(path), num_views=3).xy.shape == (1, 3, 3, 2)


@pytest.mark.parametrize("key", ["views", "by_class", "classes"])
def test_views_beside_frames_are_refused(tmp_path, key):
    data = {"frames": [{"views": _scene_views()}], key: _scene_views() if key != "by_class" else {}}
    with pytest.raises(ValueError, match=f'"{key}" beside "frames"'):
        load_detections(_write_json(tmp_path, data), num_views=3)

"""LiveAssociator: frame by frame, the same groups, points, classes and track ids as the
offline sequence functions on the same frames; nothing compiled after the first frame for
frames that fit; a frame that does not fit raises a capacity once, said so; bad frames are
refused before any work and leave the state as it was."""

import contextlib

import jax
import numpy as np
import pytest

import cdog_jax
from cdog_jax import LiveAssociator, associate_sequence
from cdog_jax.io import detections_from_array
from cdog_jax.people import _classes as people_classes
from cdog_jax.people._persons import PersonVote
from cdog_jax.synthetic import default_rig, generate_skeleton_scenes
from cdog_jax.tracking import _live as live_module
from cdog_jax.tracking._tracks import tracking_frames

M, PEOPLE, FRAMES, J = 4, 2, 6, 17
LOWERING = "/jax/core/compile/jaxpr_to_mlir_module_duration"


@pytest.fixture(scope="module")
def walk():
    """Two people walking for six frames, seen by four cameras (17 joint classes)."""
    rig = default_rig(num_views=M)
    sk = generate_skeleton_scenes(jax.random.PRNGKey(1), rig, PEOPLE, 1.0, num_frames=FRAMES)
    mask = np.asarray(sk.frames.mask)
    classes = np.where(mask, np.asarray(sk.frames.class_id), 0)
    return rig, np.asarray(sk.frames.xy, np.float32), mask, classes


def _assert_same_frame(live, offline, f, classed=True):
    a = offline.association
    valid = np.asarray(a.valid[f])
    np.testing.assert_array_equal(live.groups, np.asarray(a.groups[f])[valid])
    np.testing.assert_array_equal(live.labels, np.asarray(a.labels[f]))
    np.testing.assert_array_equal(live.track_id, offline.track_id[f][valid])
    np.testing.assert_array_equal(live.recovered, offline.recovered[f][valid])
    np.testing.assert_allclose(live.points3d, np.asarray(a.points3d[f])[valid], rtol=0, atol=1e-5)
    if classed:
        np.testing.assert_array_equal(live.group_class, offline.group_class[f][valid])
    else:
        assert live.group_class is None
    assert live.frame == f


@pytest.mark.parametrize("prior", [False, True], ids=["tracks", "temporal-prior"])
def test_same_answers_as_the_offline_sequence(walk, prior):
    rig, xy, mask, classes = walk
    offline = associate_sequence(rig, xy, mask, classes=classes, temporal_prior=prior, max_gap=1)
    live = LiveAssociator(rig, num_classes=J, temporal_prior=prior, max_gap=1)
    for f in range(FRAMES):
        _assert_same_frame(live.update(xy[f], mask[f], classes=classes[f]), offline, f)
    assert offline.num_tracks > PEOPLE * 5  # a real sequence: many joints tracked


def _one_joint(xy, mask, classes):
    """One joint alone, without its class: a point per person (this joint: seen by every
    camera in these frames; most others are hidden in some views)."""
    one = classes == 15
    return np.where(one[..., None], xy, 0.0).astype(np.float32), mask & one


def test_without_classes_same_answers_as_the_offline_sequence(walk):
    """Detections with no class: the whole frame is one scene (one class of its own)."""
    rig, xy, mask, classes = walk
    xy, mask = _one_joint(xy, mask, classes)
    offline = associate_sequence(rig, xy, mask)
    live = LiveAssociator(rig)
    for f in range(FRAMES):
        _assert_same_frame(live.update(xy[f], mask[f]), offline, f, classed=False)
    assert (np.asarray(offline.association.valid).sum(axis=1) == PEOPLE).all()


@contextlib.contextmanager
def _lowered():
    """The names of the programs JAX lowers inside the block (a list, filled as it runs)."""
    lowered = []
    listener = lambda name, secs, **kw: (  # noqa: E731
        lowered.append(kw.get("fun_name")) if name == LOWERING else None
    )
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield lowered
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def test_nothing_compiled_after_the_first_frame(walk):
    rig, xy, mask, classes = walk
    live = LiveAssociator(rig, num_classes=J, temporal_prior=True)
    live.update(xy[0], mask[0], classes=classes[0])
    with _lowered() as lowered:
        for f in range(1, FRAMES):
            keep = np.random.default_rng(f).random(mask[f].shape) > 0.2  # frames of other counts
            live.update(xy[f], mask[f] & keep, classes=classes[f])
    assert lowered == [] and live.compiles == 0


def test_frames_that_fill_half_the_slots_run_the_smaller_programs(walk, monkeypatch):
    """Frames of at most half the slots of one class in a view (4 of 8) run programs of that
    rung, the others the full rung's, both compiled on the first frame (here one of the full
    rung: the smaller rung's programs compiled on it cut to fit): the same answers as
    offline, nothing compiled after the first frame."""
    rig, xy, mask, classes = walk
    extra = 5  # five or more detections of class 0 in view 0 of frames 0 and 3: rung 8
    xy, mask, classes = (
        np.pad(a, [(0, 0), (0, 0), (0, extra)] + [(0, 0)] * (a.ndim - 3))
        for a in (xy, mask, classes)
    )
    strays = np.random.default_rng(1).uniform(100, 400, (2, extra, 2))
    xy[[0, 3], 0, -extra:], mask[[0, 3], 0, -extra:] = strays, True
    offline = associate_sequence(rig, xy, mask, classes=classes)
    live = LiveAssociator(rig, num_classes=J)
    assert (live.low_slots, live.slots) == (4, 8)
    _assert_same_frame(live.update(xy[0], mask[0], classes=classes[0]), offline, 0)
    rungs, associate = [], live_module.associate_classes_at
    monkeypatch.setattr(
        live_module,
        "associate_classes_at",
        lambda *a, **k: rungs.append(k["min_slots"]) or associate(*a, **k),
    )
    with _lowered() as lowered:
        for f in range(1, FRAMES):
            _assert_same_frame(live.update(xy[f], mask[f], classes=classes[f]), offline, f)
    assert lowered == [] and live.compiles == 0
    assert rungs == [4, 4, 8, 4, 4]


def test_sigma_fits_of_other_widths_compile_nothing(walk, monkeypatch):
    """Frames of few and many detections: each frame's σ fit runs on the narrowest table
    that holds its samples (all warmed on the first frame), the same answers as offline."""
    rig, xy, mask, _ = walk
    keep = (
        np.random.default_rng(0).random(mask.shape)
        < np.array([1, 0.4, 0.9, 0.3, 1, 0.5])[:, None, None]
    )
    mask = mask & keep
    offline = associate_sequence(rig, xy, mask)
    live = LiveAssociator(rig, slots=32)
    _assert_same_frame(live.update(xy[0], mask[0]), offline, 0, classed=False)
    widths, call = [], people_classes.call_stored

    def recorded(program, args, **static):
        if program is people_classes._pooled_table_fit:
            widths.append(static["width"])
        return call(program, args, **static)

    monkeypatch.setattr(people_classes, "call_stored", recorded)
    with _lowered() as lowered:
        for f in range(1, FRAMES):
            _assert_same_frame(live.update(xy[f], mask[f]), offline, f, classed=False)
    assert lowered == [] and live.compiles == 0
    assert len(set(widths)) > 1 and max(widths) < live._fit_widths[-1]


def test_a_held_sigma_is_the_first_trusted_estimate_and_answers_as_if_given(walk, monkeypatch):
    """sigma="held": σ estimated as "auto" does until a frame's estimate is trusted (an
    empty frame falls back: nothing held), then held: every frame answers bitwise as an
    object given that σ, and no later frame fits σ; reset forgets it."""
    rig, xy, mask, classes = walk
    first = LiveAssociator(rig, num_classes=J).update(xy[0], mask[0], classes=classes[0])
    held = LiveAssociator(rig, num_classes=J, sigma="held")
    given = LiveAssociator(rig, num_classes=J, sigma=first.sigma_px)
    # An empty frame (nothing fitted) and one of two detections a view (too few pairs).
    sparse = mask[0] & (np.cumsum(mask[0], axis=1) <= 2)
    for m in (np.zeros_like(mask[0]), sparse):
        out = held.update(xy[0], m, classes=classes[0])
        given.update(xy[0], m, classes=classes[0])
        assert held.held_sigma is None, out.sigma_px
    assert out.status & cdog_jax.Status.SIGMA_FALLBACK
    fits, fit = [], people_classes._one_table_fit
    monkeypatch.setattr(people_classes, "_one_table_fit", lambda *a: fits.append(1) or fit(*a))
    for f in range(FRAMES):
        a = held.update(xy[f], mask[f], classes=classes[f])
        b = given.update(xy[f], mask[f], classes=classes[f])
        for name in ("labels", "groups", "track_id", "recovered", "points3d", "sigma_px"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert held.held_sigma == first.sigma_px and len(fits) == 1  # frame 0's fit alone
    # An object given σ answers as the offline sequence given it.
    offline = associate_sequence(rig, xy, mask, classes=classes, sigma=first.sigma_px)
    given = LiveAssociator(rig, num_classes=J, sigma=first.sigma_px)
    for f in range(FRAMES):
        _assert_same_frame(given.update(xy[f], mask[f], classes=classes[f]), offline, f)
    held.reset()
    assert held.held_sigma is None


def test_a_frame_that_does_not_fit_raises_its_capacity_once(walk):
    """A view with more detections of one class than the programs hold (4): one warning,
    one larger program, the same answers as offline; the next such frame compiles nothing.
    The larger program is the default's (8 slots), which the other tests here share."""
    rig, xy, mask, classes = walk
    extra = 8  # stray detections of class 0 in view 0 of frames 1 and 2 (no nose seen there)
    xy, mask, classes = (
        np.pad(a[:3], [(0, 0), (0, 0), (0, extra)] + [(0, 0)] * (a.ndim - 3))
        for a in (xy, mask, classes)
    )
    strays = np.random.default_rng(0).uniform(100, 400, (2, extra, 2))
    xy[1:, 0, -extra:], mask[1:, 0, -extra:] = strays, True
    live = LiveAssociator(rig, num_classes=J, slots=4)
    offline = associate_sequence(rig, xy, mask, classes=classes)
    _assert_same_frame(live.update(xy[0], mask[0], classes=classes[0]), offline, 0)
    with pytest.warns(UserWarning, match="8 detections of one class in one view does not fit"):
        _assert_same_frame(live.update(xy[1], mask[1], classes=classes[1]), offline, 1)
    assert live.compiles == 1 and live.slots == 8
    _assert_same_frame(live.update(xy[2], mask[2], classes=classes[2]), offline, 2)
    assert live.compiles == 1


def test_reads_a_detections_frame_and_reset_starts_over(walk):
    rig, xy, mask, classes = walk
    # One joint: the programs of the test without classes above (this file's worker holds them).
    xy, mask = _one_joint(xy, mask, classes)
    det = detections_from_array(np.where(mask[0, ..., None], xy[0], np.nan), missing="nan")
    live = LiveAssociator(rig)
    first = live.update(det)
    assert len(first.track_id) == PEOPLE
    assert live.update(det).frame == 1
    live.reset()
    again = live.update(det)
    assert again.frame == 0
    np.testing.assert_array_equal(again.track_id, first.track_id)


def test_bad_frames_refused_and_state_kept(walk):
    rig, xy, mask, classes = walk
    live = LiveAssociator(rig, num_classes=J)
    with pytest.raises(ValueError, match="give the frame's classes"):
        live.update(xy[0], mask[0])
    slot = int(np.flatnonzero(mask[0, 0])[0])
    with pytest.raises(ValueError, match=rf"class 17 at view 0, slot {slot} is not in \[0, 17\)"):
        live.update(
            xy[0], mask[0], classes=np.where(np.arange(xy.shape[2]) == slot, 17, classes[0])
        )
    with pytest.raises(ValueError, match=r"xy must have shape \(M, P, 2\)"):
        live.update(xy[:2], mask[:2], classes=classes[:2])
    assert live.frame == 0
    with pytest.raises(ValueError, match="num_classes must be a positive int"):
        LiveAssociator(rig, num_classes=0)
    with pytest.raises(ValueError, match="sigma must be 'auto', 'held' or a finite number"):
        LiveAssociator(rig, sigma=-1.0)
    with pytest.raises(ValueError, match="sigma must be 'auto', 'held'"):
        LiveAssociator(rig, sigma="hold")
    with pytest.raises(TypeError):
        LiveAssociator(np.eye(3))
    assert cdog_jax.LiveFrame._fields[0] == "frame"


def test_person_vote_same_answers_as_offline(walk):
    """With each detection's per-view skeleton (the person vote), frame by frame as offline."""
    rig, xy, mask, classes = walk
    sk = generate_skeleton_scenes(jax.random.PRNGKey(1), rig, PEOPLE, 1.0, num_frames=FRAMES)
    person = np.where(mask, np.asarray(sk.frames.instance) // J, -1)
    # Each view numbers its people in its own order, a new one every frame (a 2D detector's).
    shift = np.arange(FRAMES)[:, None, None] + np.arange(M)[None, :, None]
    person = np.where(person >= 0, (person + shift) % PEOPLE, -1)
    offline = associate_sequence(rig, xy[:3], mask[:3], classes=classes[:3], instances=person[:3])
    people = cdog_jax.identify_people(offline, person[:3])
    live = LiveAssociator(rig, num_classes=J, person_vote=True)
    for f in range(3):
        out = live.update(xy[f], mask[f], classes=classes[f], instances=person[f])
        _assert_same_frame(out, offline, f)
        # every group's person id as offline: ids kept over frames through the tracks
        np.testing.assert_array_equal(
            out.person_id, people.group_person[f][np.asarray(offline.association.valid[f])]
        )
        assert (
            sorted(set(out.person_id.tolist())) == [0, 1]
            and out.merged_people == out.split_people == ()
        )
    plain = LiveAssociator(rig, num_classes=J).update(xy[0], mask[0], classes=classes[0])
    assert plain.person_id is None and plain.merged_people == ()  # no instances, no people


def test_the_documented_loop_runs(capsys):
    import os
    import re

    with open(
        os.path.join(os.path.dirname(__file__), "..", "docs", "LIVE.md"), encoding="utf-8"
    ) as f:
        block = re.search(r"```python\n(.*?)```", f.read(), re.S).group(1)
    assert len(block.splitlines()) <= 20
    exec(compile(block, "docs/LIVE.md", "exec"), {"__name__": "__live__"})
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 5 and all(line.startswith(f"frame {f}: ") for f, line in enumerate(lines))


@pytest.mark.parametrize("rows", [16, 64], ids=["rows-cut", "rows-enough"])
def test_the_frame_table_made_on_the_device_is_the_hosts(walk, rows):
    """The tracker's program makes a frame's table from its class scenes' results as the
    host does (the scenes mapped back to the frame, then the tracker's rows): the same
    groups, labels, classes and points, bitwise, the first ``rows`` groups kept when the
    frame holds more (the object then raises its rows and runs the frame again)."""
    rig, xy, mask, classes = walk
    shapes = dict(num_classes=J, min_scenes=J, min_slots=8, batch_size=J, sigma=2.0)
    args = (rig, xy[:1], mask[:1], classes[:1])
    scenes = people_classes.associate_classes_at(*args, scenes_only=True, **shapes)
    host = people_classes.associate_classes_at(*args, on_host=True, **shapes)
    a = host.association
    found = int(a.num_groups[0])
    assert found > 16  # the cut is exercised
    oracle = tracking_frames(
        a, host.group_class, a.labels, xy[:1], mask[:1], classes[:1], None, rows, True
    )
    table = jax.jit(people_classes.frame_of_scenes, static_argnums=(3, 4, 5))(
        scenes.result,
        scenes.scenes.slot.astype(np.int32),
        scenes.scenes.cls.astype(np.int32),
        mask.shape[2],
        rows,
        2 * rows,
    )
    X, valid, cls, groups, bpe, err_px, labels, got_found, tau = (np.asarray(t) for t in table)
    assert int(got_found) == found and tau == oracle.err_gate_px[0]
    for name, got in (("X", X), ("valid", valid), ("groups", groups), ("bpe", bpe)):
        np.testing.assert_array_equal(got, getattr(oracle, name)[0], err_msg=name)
    np.testing.assert_array_equal(err_px, oracle.err_px[0])
    np.testing.assert_array_equal(labels, oracle.labels[0])
    np.testing.assert_array_equal(cls[valid], oracle.cls[0][valid])


@pytest.mark.parametrize("rows", [16, 64], ids=["rows-cut", "rows-enough"])
def test_the_vote_on_the_scenes_is_the_vote_on_the_frame(walk, rows):
    """The person vote on a frame's class scenes, their table made on the device
    (:func:`vote_on_scenes`, as the live object runs it), returns the arrays of the vote on
    the frame mapped back on the host, bitwise; a frame of more groups than the table's
    rows gets ``None`` (the object then votes on the host's table)."""
    rig, xy, mask, classes = walk
    sk = generate_skeleton_scenes(jax.random.PRNGKey(1), rig, PEOPLE, 1.0, num_frames=FRAMES)
    person = np.where(mask[:1], np.asarray(sk.frames.instance[:1]) // J, -1)
    # Two joints of a view that sees both people given the other person: the vote detaches
    # them, and changes and triangulates their groups again.
    view = next(m for m in range(M) if set(person[0, m][person[0, m] >= 0].tolist()) == {0, 1})
    swapped = np.flatnonzero(person[0, view] == 0)[:2]
    person[0, view, swapped] = 1
    shapes = dict(num_classes=J, min_scenes=J, min_slots=8, batch_size=J, sigma=2.0)
    args = (rig, xy[:1], mask[:1], classes[:1])
    scenes = people_classes.associate_classes_at(*args, scenes_only=True, **shapes)
    got = people_classes.vote_on_scenes(
        rig, scenes, *args[1:], person, PersonVote(), rows=rows, num_classes=J
    )
    if rows == 16:  # the frame holds more groups
        assert got is None
        return
    host = people_classes.associate_classes_at(
        *args, instances=person, person_vote=True, min_vote_rows=rows, on_host=True, **shapes
    )
    unvoted = people_classes.associate_classes_at(*args, on_host=True, **shapes).association
    changed = host.association.groups.shape != unvoted.groups.shape or not np.array_equal(
        host.association.groups, unvoted.groups
    )
    assert changed  # the vote changed the frame's groups
    for name in host.association.__dataclass_fields__:
        want, have = getattr(host.association, name), getattr(got.association, name)
        assert want.dtype == have.dtype, name
        np.testing.assert_array_equal(have, want, err_msg=name)
    np.testing.assert_array_equal(got.group_class, host.group_class)
    assert got.num_classes == host.num_classes == J and got.class_names is None

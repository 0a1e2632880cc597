"""People as the output (``identify_people``): every frame's joint groups become people with
ids kept over frames (through the tracks of their joints), skeletons ``(F, N, C, 3)`` with
NaN for a missing joint, and flags where two people merge or one splits."""

from types import SimpleNamespace

import jax
import numpy as np
import pytest

from cdog_jax import associate_sequence, identify_people
from cdog_jax.people._persons import PersonLinker
from cdog_jax.synthetic import SKELETON_JOINTS, generate_skeleton_scenes, ring_rig

M, F, K = 4, 6, 3  # views, frames, people


@pytest.fixture(scope="module")
def walk():
    """Three walking people seen by four cameras over six frames; each view numbers its
    people in a new random order every frame (a 2D detector's order is no identity)."""
    rig = ring_rig(num_views=M)
    sk = generate_skeleton_scenes(jax.random.PRNGKey(4), rig, K, 1.0, num_frames=F, max_people=K)
    xy, mask, cls = (np.asarray(a) for a in (sk.frames.xy, sk.frames.mask, sk.frames.class_id))
    person = np.asarray(sk.person)
    order = np.stack(
        [[np.random.default_rng(10 * f + m).permutation(K) for m in range(M)] for f in range(F)]
    )
    instances = np.where(person >= 0, np.take_along_axis(order, np.maximum(person, 0), axis=2), -1)
    tracked = associate_sequence(
        rig, xy, mask, classes=np.where(mask, cls, 0), sigma=1.0, class_names=SKELETON_JOINTS
    )
    return tracked, instances, person, np.asarray(sk.joints3d), cls


def test_people_keep_their_ids_and_their_joints(walk):
    tracked, instances, person, joints3d, cls = walk
    people = identify_people(tracked, instances)
    assert people.points.shape == (F, K, len(SKELETON_JOINTS), 3) and people.num_people == K
    assert people.class_names == SKELETON_JOINTS
    assert not people.merged.any() and not people.split.any() and not people.mixed.any()
    # The same id on the same true person in every frame.
    ids = np.sort(people.person_id, axis=1)
    np.testing.assert_array_equal(ids, np.broadcast_to(np.arange(K), (F, K)))
    for f in range(F):
        for n, pid in enumerate(people.person_id[f]):
            err = np.linalg.norm(people.points[f, n][None] - joints3d[f], axis=-1).mean(
                axis=1
            )  # (K,) per true person
            truth = int(np.argmin(err))
            assert err[truth] < 0.02
            first = np.flatnonzero(people.person_id[0] == pid)[0]
            assert (
                np.argmin(
                    np.linalg.norm(people.points[0, first][None] - joints3d[0], axis=-1).mean(
                        axis=1
                    )
                )
                == truth
            )
    # Every valid group's person id is its skeleton's, and the skeleton holds its point.
    a = tracked.association
    valid, gp = np.asarray(a.valid), people.group_person
    assert np.all(gp[valid] >= 0) and np.all(gp[~valid] == -1)
    for f, g in zip(*np.nonzero(valid)):
        n = np.flatnonzero(people.person_id[f] == gp[f, g])[0]
        np.testing.assert_allclose(
            people.points[f, n, tracked.group_class[f, g]], np.asarray(a.points3d)[f, g], atol=1e-6
        )


def test_missing_joints_are_nan_and_unknown_instances_have_no_person(walk):
    tracked, instances, person, joints3d, cls = walk
    nose = SKELETON_JOINTS.index("nose")
    people = identify_people(
        tracked, np.where(cls == nose, -1, instances)
    )  # no nose has a known person
    assert np.isnan(people.points[:, :, nose]).all()
    assert np.isfinite(people.points[:, :, nose + 1]).all()
    gc = tracked.group_class
    assert np.all(people.group_person[gc == nose] == -1)


def test_ids_per_frame_without_tracks(walk):
    tracked, instances, *_ = walk
    untracked = SimpleNamespace(
        association=tracked.association,
        group_class=tracked.group_class,
        num_classes=tracked.num_classes,
        class_names=None,
    )
    people = identify_people(untracked, instances)
    assert people.num_people == F * K  # a new id for every person of every frame
    np.testing.assert_array_equal(people.person_id, np.arange(F * K).reshape(F, K))


def _one_frame(groups, group_class, instances):
    """A one-frame classed result from a group table (points: the group's row index)."""
    groups = np.asarray(groups)[None]
    G = groups.shape[1]
    assoc = SimpleNamespace(
        labels=np.full((1, groups.shape[2], 8), -1),
        groups=groups,
        valid=np.ones((1, G), bool),
        points3d=np.arange(G, dtype=np.float32)[None, :, None].repeat(3, -1),
        n_views=(groups >= 0).sum(-1),
        err_px=np.zeros((1, G), np.float32),
    )
    return SimpleNamespace(
        association=assoc,
        group_class=np.asarray(group_class)[None],
        num_classes=3,
        class_names=None,
    )


def test_a_person_with_two_joints_of_one_class_is_flagged_merged():
    # Four views; every view's instance 0 is one person (joints 1 and 2 link all four nodes);
    # class 0 is two groups: views 0+1 and views 2+3 (slot 0 of every view).
    instances = np.zeros((1, 4, 8), np.int64)
    groups = [[0, 0, -1, -1], [-1, -1, 0, 0], [1, 1, 1, 1], [2, 2, 2, 2]]
    people = identify_people(_one_frame(groups, [0, 0, 1, 2], instances), instances)
    assert people.person_id[0].tolist() == [0] and people.merged[0, 0] and not people.split.any()
    # The joint kept is one of them, not a mix: the point of group 0 or group 1.
    assert people.points[0, 0, 0].tolist() in ([0.0] * 3, [1.0] * 3)


def test_a_group_of_two_people_seen_in_one_view_is_mixed():
    # Views 0–2 see two people (instances 0 and 1); the class-0 group takes person 1's
    # detection in view 2 into person 0's group.
    instances = np.tile(np.array([0, 1, 0, 1, 0, 1, -1, -1]), (1, 3, 1))
    groups = [[0, 0, 1], [1, 1, -1], [2, 2, 2], [3, 3, 3], [4, 4, 4], [5, 5, 5]]
    people = identify_people(_one_frame(groups, [0, 0, 1, 1, 2, 2], instances), instances)
    assert people.mixed[0].tolist() == [True, False, False, False, False, False]
    assert people.group_person[0].tolist() == [0, 1, 0, 1, 0, 1]


def test_linker_flags_merges_and_splits():
    link = PersonLinker(min_votes=2)
    tracks = np.array([0, 1, 2, 3])
    ids, merged, split = link.step(np.array([0, 0, 1, 1]), tracks)
    assert ids.tolist() == [0, 1] and not merged.any() and not split.any()
    ids, merged, split = link.step(np.array([0, 0, 0, 0]), tracks)  # the two become one
    assert ids.tolist() == [0] and merged.tolist() == [True] and not split.any()
    ids, merged, split = link.step(np.array([1, 1, 0, 0]), tracks)  # and part again
    assert ids.tolist() == [0, 2] and split.tolist() == [True, True] and not merged.any()
    ids, merged, split = link.step(np.array([1, 1, 0, 0]), tracks)  # ids stay, no flag
    assert ids.tolist() == [0, 2] and not merged.any() and not split.any()
    ids, _, _ = link.step(
        np.array([0, -1, 0, 1]), np.array([9, 0, 2, 10])
    )  # a new track joins a known person
    assert ids.tolist() == [0, 3]


def test_bad_arguments_refused(walk):
    tracked, instances, *_ = walk
    with pytest.raises(ValueError, match="instances must have the shape"):
        identify_people(tracked, instances[:, :2])
    with pytest.raises(ValueError, match="classed result"):
        identify_people(tracked._replace(group_class=None, num_classes=None), instances)


def test_writers_carry_the_people(walk, tmp_path):
    from cdog_jax.io import (
        load_trc,
        save_association_csv,
        save_association_npz,
        save_people_trc,
        save_trc,
    )
    from cdog_jax.io._trc import track_markers

    tracked, instances, *_ = walk
    people = identify_people(tracked, instances)
    save_association_npz(tmp_path / "r.npz", tracked, people=people)
    with np.load(tmp_path / "r.npz") as z:
        np.testing.assert_array_equal(z["person_id"], people.group_person)
        np.testing.assert_array_equal(z["people_points"], people.points)
        np.testing.assert_array_equal(z["people_id"], people.person_id)
        assert z["mixed"].shape == z["people_merged"].shape[:1] + tracked.track_id.shape[1:]
    save_association_csv(tmp_path / "r.csv", tracked, people=people)
    rows = [line.split(",") for line in (tmp_path / "r.csv").read_text().splitlines()[2:]]
    a = tracked.association
    f, g = np.nonzero(np.asarray(a.valid))
    assert [int(r[-1]) for r in rows] == people.group_person[f, g].tolist()
    written = save_people_trc(tmp_path / "p.trc", people, rate=10)
    assert [w.rsplit("/", 1)[-1] for w in written] == [
        "p_person0.trc",
        "p_person1.trc",
        "p_person2.trc",
    ]
    for pid, w in enumerate(written):
        f, n = np.nonzero(people.person_id == pid)
        np.testing.assert_allclose(load_trc(w).markers[f], people.points[f, n], rtol=1e-6)
    markers, names = track_markers(tracked)  # without people: one marker per track
    assert markers.shape == (F, tracked.num_tracks, 3) and names[0].endswith("_0")
    assert names[0].rsplit("_", 1)[0] in SKELETON_JOINTS
    save_trc(tmp_path / "t.trc", markers, names, rate=10)
    assert load_trc(tmp_path / "t.trc").names == names
    with pytest.raises(ValueError, match="People of this result"):
        save_association_csv(
            tmp_path / "x.csv",
            tracked,
            people=people._replace(group_person=people.group_person[:2]),
        )


def test_frames_whose_people_no_group_holds_have_no_person():
    """Instances known, yet no group (people seen in one view only), or groups none of whose
    members has a known instance: no person, no crash, offline and live."""
    instances = np.full((1, 4, 8), -1, np.int64)
    instances[0, 0, :2] = 0  # one view sees a person; the groups hold none of it
    people = identify_people(_one_frame([[2, 2, 2, 2]], [0], instances), instances)
    assert people.group_person[0].tolist() == [-1] and (people.person_id[0] == -1).all()
    people = identify_people(_one_frame([[-1, -1, -1, -1]], [-1], instances), instances)
    assert people.group_person[0].tolist() == [-1]


def test_a_live_frame_of_people_in_one_view_has_no_group_and_no_person():
    from cdog_jax import LiveAssociator
    from cdog_jax.synthetic import default_rig

    live = LiveAssociator(default_rig(num_views=3), num_classes=2)
    xy = np.zeros((3, 2, 2), np.float32)
    xy[0] = [[100, 100], [200, 200]]
    mask = np.zeros((3, 2), bool)
    mask[0] = True  # one person's two joints, seen by view 0 alone
    classes, instances = np.array([[0, 1], [0, 0], [0, 0]]), np.array([[0, 0], [-1, -1], [-1, -1]])
    out = live.update(xy, mask, classes=classes, instances=instances)
    assert len(out.groups) == 0 and out.person_id.shape == (0,) and (out.labels == -1).all()

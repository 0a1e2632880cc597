"""Track ids and the temporal prior: ids stay with a point while it is seen (slots shuffled
or not), a point that vanishes comes back with a new id, a group the association missed is
recovered by the prior with its old id (and only within the gates), the linking equals a
plain NumPy greedy matching, every output file carries the ids, and bad input is refused."""

import csv
import json
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import project_np, ring_rig, x64

from cdog_jax import associate_batch, associate_sequence, track_groups
from cdog_jax.io import save_association_csv, save_association_json, save_association_npz

F, M = 3, 3
STEP = np.array([0.05, 0.0, 0.0])  # per frame, scene units (≈ 13 px)
X0 = np.array([[0.2, 0.0, 0.1], [-0.3, 0.2, 0.0]])


@pytest.fixture(scope="module")
def seq():
    """2 points walking over 3 frames in 3 views, noise free; frame 1 swaps the slots."""
    rig = ring_rig(num_views=M)
    truth = np.stack([X0 + STEP * f for f in range(F)])  # (F, 2, 3)
    xy = np.zeros((F, M, 2, 2), np.float32)
    instance = np.zeros((F, M, 2), np.int64)
    for f in range(F):
        p, _ = project_np(rig, truth[f])
        order = [1, 0] if f == 1 else [0, 1]
        xy[f], instance[f] = p[:, order], np.array(order)[None]
    mask = np.ones((F, M, 2), bool)
    result = associate_batch(rig, xy, mask, method="paper", sigma=1.0)
    return SimpleNamespace(rig=rig, xy=xy, mask=mask, instance=instance, truth=truth, result=result)


def _point_of_group(tracked, f, g, instance):
    labels = np.asarray(tracked.association.labels[f])
    ids = np.unique(instance[f][labels == g])
    assert ids.size == 1
    return int(ids[0])


def _ids_by_point(tracked, instance):
    """``{(frame, true point): track id}`` of every valid group."""
    out = {}
    for f in range(tracked.track_id.shape[0]):
        for g in np.flatnonzero(np.asarray(tracked.association.valid[f])):
            out[f, _point_of_group(tracked, f, g, instance)] = int(tracked.track_id[f, g])
    return out


def _without_group(result, f, point, instance):
    """``result`` with the group of ``point`` in frame ``f`` removed (its detections unassigned)."""
    labels, valid = np.asarray(result.labels).copy(), np.asarray(result.valid).copy()
    g = int(np.unique(labels[f][instance[f] == point])[0])
    labels[f][labels[f] == g] = -1
    valid[f, g] = False
    return SimpleNamespace(
        **{
            **{k: getattr(result, k) for k in result.__dataclass_fields__},
            "labels": labels,
            "valid": valid,
        }
    )


def test_ids_stay_with_their_points(seq):
    tracked = track_groups(seq.rig, seq.result)
    ids = _ids_by_point(tracked, seq.instance)
    assert ids == {(f, p): ids[0, p] for f in range(F) for p in (0, 1)}
    assert sorted({ids[0, 0], ids[0, 1]}) == [0, 1] and tracked.num_tracks == 2
    assert (np.asarray(tracked.track_id)[~np.asarray(tracked.association.valid)] == -1).all()


def test_a_point_that_vanishes_returns_with_a_new_id(seq):
    mask = seq.mask.copy()
    mask[1, 1:][seq.instance[1, 1:] == 0] = False  # point 0 seen in view 0 only in frame 1
    for prior in (False, True):  # one view: nothing to recover
        tracked = associate_sequence(
            seq.rig, seq.xy, mask, method="paper", sigma=1.0, temporal_prior=prior
        )
        ids = _ids_by_point(tracked, seq.instance)
        assert (1, 0) not in ids
        assert ids[0, 1] == ids[1, 1] == ids[2, 1]
        assert ids[2, 0] == 2 and tracked.num_tracks == 3, prior
    bridged = associate_sequence(seq.rig, seq.xy, mask, method="paper", sigma=1.0, max_gap=1)
    ids = _ids_by_point(bridged, seq.instance)
    assert ids[0, 0] == ids[2, 0] != ids[0, 1] and bridged.num_tracks == 2


def test_the_prior_recovers_a_missed_group_with_its_id(seq):
    missed = _without_group(seq.result, 1, 0, seq.instance)
    plain = track_groups(seq.rig, missed)
    assert _ids_by_point(plain, seq.instance)[2, 0] == 2  # the track broke
    tracked = track_groups(seq.rig, missed, xy=seq.xy, mask=seq.mask, temporal_prior=True)
    ids = _ids_by_point(tracked, seq.instance)
    assert ids == {(f, p): ids[0, p] for f in range(F) for p in (0, 1)} and tracked.num_tracks == 2
    rec = np.asarray(tracked.recovered)
    assert rec.sum() == 1
    f, g = np.argwhere(rec)[0]
    assert f == 1 and int(tracked.association.n_views[f, g]) == M
    np.testing.assert_allclose(
        np.asarray(tracked.association.points3d[f, g]), seq.truth[1, 0], atol=1e-3
    )
    assert int(tracked.association.num_groups[1]) == 2 and int(tracked.unplaced.sum()) == 0


def test_the_prior_respects_its_gates(seq):
    missed = _without_group(seq.result, 1, 0, seq.instance)
    far = track_groups(
        seq.rig, missed, xy=seq.xy, mask=seq.mask, temporal_prior=True, max_step_px=2.0
    )  # the step is ≈ 13 px
    assert not np.asarray(far.recovered).any()
    xy = seq.xy.copy()
    xy[1, 0][seq.instance[1, 0] == 0] += 8.0  # one view off by 11 px: dropped, the other two agree
    loose = track_groups(seq.rig, missed, xy=xy, mask=seq.mask, temporal_prior=True, max_err_px=3.0)
    f, g = np.argwhere(np.asarray(loose.recovered))[0]
    assert (f, int(loose.association.n_views[f, g])) == (1, 2)
    lens = track_groups(
        seq.rig,
        missed,
        xy=xy,
        mask=seq.mask,
        temporal_prior=True,
        max_err_px=3.0,
        dist=np.zeros((M, 5), np.float32),
    )
    np.testing.assert_array_equal(
        lens.association.labels, loose.association.labels
    )  # a lens that does nothing changes nothing


def test_sequences_vmap_as_a_loop(seq):
    """The scan is a pure function of one sequence: vmapped over two, it equals two calls."""
    from cdog_jax.tracking._tracks import _Frame, initial_tracks, track_sequence

    G, P = seq.result.valid.shape[1], seq.mask.shape[2]
    tau = np.asarray(seq.result.tau_px)
    a = seq.result
    frames = _Frame(
        jnp.concatenate([a.points3d, jnp.zeros_like(a.points3d)], 1),
        jnp.concatenate([a.valid, jnp.zeros_like(a.valid)], 1),
        jnp.zeros((F, 2 * G), jnp.int32),
        jnp.concatenate([a.groups, jnp.full_like(a.groups, -1)], 1),
        jnp.zeros((F, 2 * G)),
        jnp.zeros((F, 2 * G)),
        a.labels,
        jnp.asarray(seq.xy),
        jnp.asarray(seq.mask),
        jnp.zeros((F, M, P), jnp.int32),
        jnp.asarray(tau),
    )
    missed = frames._replace(  # group 0 of frame 1 removed, its detections unassigned
        valid=frames.valid.at[1, 0].set(False),
        labels=frames.labels.at[1].set(jnp.where(frames.labels[1] == 0, -1, frames.labels[1])),
    )
    both = jax.tree.map(lambda x, y: jnp.stack([x, y]), frames, missed)
    init = initial_tracks(2 * G, 0, np.float32)
    run = lambda fr: track_sequence(
        seq.rig,
        init,
        fr,
        jnp.float32(np.nan),
        jnp.float32(60.0),
        prior=True,
        min_views=2,
        max_gap=0,
    )[1]  # noqa: E731
    batched = jax.vmap(run)(both)
    for i, fr in enumerate((frames, missed)):
        jax.tree.map(lambda b, one: np.testing.assert_array_equal(b[i], one), batched, run(fr))
    assert bool(batched.recovered[1].any()) and not bool(batched.recovered[0].any())


def _link_oracle(X, valid, cls, max_step, max_gap):
    """Plain NumPy: the tracks alive (seen within ``max_gap`` frames before, at their last
    point) and this frame's groups, pairs within the gate times the frames since, cheapest
    first."""
    ids = np.full(valid.shape, -1)
    alive = {}  # track id -> (last point, class, frames since seen - 1)
    next_id = 0
    for f in range(valid.shape[0]):
        pairs = sorted(
            (float(np.linalg.norm(x.astype(np.float64) - X[f, g])), t, g)
            for t, (x, c, age) in alive.items()
            for g in np.flatnonzero(valid[f])
            if c == cls[f, g]
            and np.linalg.norm(x.astype(np.float64) - X[f, g]) <= max_step * (age + 1)
        )
        taken_track, taken = set(), set()
        for _d, t, g in pairs:
            if t not in taken_track and g not in taken:
                ids[f, g] = t
                taken_track.add(t)
                taken.add(g)
        for g in np.flatnonzero(valid[f]):
            if ids[f, g] < 0:
                ids[f, g], next_id = next_id, next_id + 1
        alive = {
            t: (x, c, age + 1)
            for t, (x, c, age) in alive.items()
            if t not in taken_track and age + 1 <= max_gap
        }
        alive.update({int(ids[f, g]): (X[f, g], cls[f, g], 0) for g in np.flatnonzero(valid[f])})
    return ids


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("max_gap", [0, 1])
def test_linking_equals_the_numpy_oracle(seed, max_gap):
    rng = np.random.default_rng(seed)
    Fr, G, P = 5, 6, 2
    count = rng.integers(0, G + 1, Fr)
    valid = np.arange(G)[None, :] < count[:, None]  # valid rows first, as every result has them
    X = rng.uniform(-0.5, 0.5, (Fr, G, 3)).astype(np.float32)
    X[1:] = np.where(
        rng.random((Fr - 1, G, 1)) < 0.7, X[:-1] + rng.normal(0, 0.1, (Fr - 1, G, 3)), X[1:]
    ).astype(np.float32)
    cls = rng.integers(0, 2, (Fr, G)).astype(np.int32)
    result = SimpleNamespace(
        association=SimpleNamespace(
            labels=np.full((Fr, M, P), -1, np.int32),
            groups=np.full((Fr, G, M), -1, np.int32),
            valid=valid,
            points3d=np.where(valid[..., None], X, np.nan),
            bpe=np.zeros((Fr, G), np.float32),
            err_px=np.zeros((Fr, G), np.float32),
            n_views=np.zeros((Fr, G), np.int32),
            sigma_px=np.ones(Fr, np.float32),
            tau_px=np.ones(Fr, np.float32),
            status=np.zeros(Fr, np.int32),
        ),
        group_class=np.where(valid, cls, -1),
        class_names=None,
        num_classes=2,
    )
    tracked = track_groups(ring_rig(num_views=M), result, max_step=0.25, max_gap=max_gap)
    np.testing.assert_array_equal(tracked.track_id, _link_oracle(X, valid, cls, 0.25, max_gap))
    np.testing.assert_array_equal(tracked.group_class, np.where(valid, cls, -1))


def test_output_files_carry_track_ids(seq, tmp_path):
    missed = _without_group(seq.result, 1, 0, seq.instance)
    tracked = track_groups(seq.rig, missed, xy=seq.xy, mask=seq.mask, temporal_prior=True)
    save_association_json(tmp_path / "a.json", tracked, seq.xy, seq.mask)
    frames = json.loads((tmp_path / "a.json").read_text())["frames"]
    got = [[(g["id"], g["track"], g["recovered"]) for g in fr["groups"]] for fr in frames]
    valid, tid, rec = (
        np.asarray(a) for a in (tracked.association.valid, tracked.track_id, tracked.recovered)
    )
    assert got == [
        [(int(g), int(tid[f, g]), bool(rec[f, g])) for g in np.flatnonzero(valid[f])]
        for f in range(F)
    ]
    save_association_npz(tmp_path / "a.npz", tracked)
    with np.load(tmp_path / "a.npz") as z:
        np.testing.assert_array_equal(z["track_id"], tid)
        np.testing.assert_array_equal(z["recovered"], rec)
    save_association_csv(tmp_path / "a.csv", tracked)
    rows = list(
        csv.reader(
            line
            for line in (tmp_path / "a.csv").read_text().splitlines()
            if not line.startswith("#")
        )
    )
    assert rows[0][-1] == "track"
    assert [(int(r[0]), int(r[1]), int(r[-1])) for r in rows[1:]] == [
        (f, int(g), int(tid[f, g])) for f in range(F) for g in np.flatnonzero(valid[f])
    ]


def test_bad_input_is_refused_before_any_work(seq):
    with pytest.raises(TypeError, match="track_groups: result must be an Association"):
        track_groups(seq.rig, seq.xy)
    one = jax.tree.map(lambda a: a[0], seq.result)
    with pytest.raises(ValueError, match=r"result must hold F frames.*\(3, 2\)"):
        track_groups(seq.rig, one)
    with pytest.raises(ValueError, match="rig has 4"):
        track_groups(ring_rig(num_views=4), seq.result)
    for name, value in (
        ("max_step", -1.0),
        ("max_step_px", float("nan")),
        ("max_err_px", 0.0),
        ("max_step_px", float("inf")),
    ):
        with pytest.raises(ValueError, match=f"{name} must be a finite number > 0.*got {value!r}"):
            track_groups(seq.rig, seq.result, **{name: value})
    with pytest.raises(ValueError, match="max_gap must be an int >= 0; got -1"):
        track_groups(seq.rig, seq.result, max_gap=-1)
    with pytest.raises(ValueError, match="min_views must be an int in \\[2, 3\\]; got 4"):
        track_groups(seq.rig, seq.result, min_views=4)
    with pytest.raises(ValueError, match="temporal_prior=True needs the detections"):
        track_groups(seq.rig, seq.result, temporal_prior=True)
    with pytest.raises(
        ValueError, match=r"xy and mask must have shapes \(3, 3, 2, 2\).*got xy \(3, 3, 3, 2\)"
    ):
        track_groups(
            seq.rig, seq.result, xy=np.zeros((F, M, 3, 2)), mask=seq.mask, temporal_prior=True
        )
    classed = SimpleNamespace(
        association=seq.result,
        group_class=np.zeros((F, 2), np.int32),
        class_names=None,
        num_classes=1,
    )
    with pytest.raises(ValueError, match="needs the detections' classes"):
        track_groups(seq.rig, classed, xy=seq.xy, mask=seq.mask, temporal_prior=True)
    with pytest.raises(
        ValueError, match=r"classes must be integer class ids of shape \(3, 3, 2\); got \(3, 3\)"
    ):
        track_groups(
            seq.rig,
            classed,
            xy=seq.xy,
            mask=seq.mask,
            classes=np.zeros((F, M), np.int32),
            temporal_prior=True,
        )


def test_float64_links_and_recovers_alike(seq):
    """float64 with ``max_gap=1`` against the float32 program the other tests compile
    (``max_gap=0``): no track goes unseen here, so the gap changes nothing."""
    missed = _without_group(seq.result, 1, 0, seq.instance)
    want = track_groups(seq.rig, missed, xy=seq.xy, mask=seq.mask, temporal_prior=True)
    assert np.asarray(want.recovered).sum() == 1
    with x64():
        rig = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), seq.rig)
        wide = SimpleNamespace(
            **{
                k: np.asarray(v, np.float64)
                if np.issubdtype(np.asarray(v).dtype, np.floating)
                else v
                for k, v in vars(missed).items()
            }
        )
        got = track_groups(
            rig, wide, xy=seq.xy.astype(np.float64), mask=seq.mask, temporal_prior=True, max_gap=1
        )
        assert got.association.points3d.dtype == jnp.float64
    np.testing.assert_array_equal(got.track_id, want.track_id)
    np.testing.assert_array_equal(got.recovered, want.recovered)
    np.testing.assert_allclose(
        np.asarray(got.association.points3d), np.asarray(want.association.points3d), atol=1e-4
    )


def _cheapest_first_oracle(cost):
    """Plain NumPy: one pair a step, the cheapest left (ties: the smaller flat index)."""
    cost, match = cost.astype(np.float64), np.full(cost.shape[0], -1)
    while np.isfinite(cost).any():
        a, b = np.unravel_index(np.argmin(cost), cost.shape)
        match[a], cost[a, :], cost[:, b] = b, np.inf, np.inf
    return match


@pytest.mark.parametrize("seed", range(4))
def test_matching_in_rounds_equals_cheapest_first(seed):
    """The rounds of mutual best pairs give the cheapest-first matching, ties included."""
    from cdog_jax.tracking._matching import greedy_match

    match = jax.jit(greedy_match)
    rng = np.random.default_rng(seed)
    for _ in range(40):
        A, B = rng.integers(1, 10, 2)
        cost = rng.integers(0, 4, (A, B)).astype(np.float32)  # few values: many ties
        cost[rng.random((A, B)) < 0.4] = np.inf
        np.testing.assert_array_equal(np.asarray(match(cost)), _cheapest_first_oracle(cost))


@pytest.mark.parametrize("seed", range(3))
def test_the_prior_finds_the_same_detections_among_the_free_ones_packed(seed):
    """The prior's search on each view's free detections packed to the front gives the
    slots of the search on every slot, ties (repeated pixels, equal distances) included,
    and the slots of the plain NumPy cheapest-first matching."""
    from cdog_jax.tracking._temporal_prior import _nearest_free, _nearest_free_packed

    rng = np.random.default_rng(seed)
    T, M, P = 14, 3, 24
    xy = rng.integers(0, 12, (M, P, 2)).astype(np.float32)  # few pixels: many ties
    xy[:, 7] = xy[:, 2]
    pick = rng.integers(0, P, (T, M))
    pred = (xy[np.arange(M)[None, :], pick] + rng.integers(-1, 2, (T, M, 2))).astype(np.float32)
    free = rng.random((M, P)) < 0.5
    track_ok = rng.random((T, M)) < 0.8
    prev_class = rng.integers(0, 2, T)
    det_class = rng.integers(0, 2, (M, P))
    gate = np.full(T, 3.0, np.float32)
    args = (pred, track_ok, prev_class, gate, xy, free, det_class)
    full = np.asarray(jax.jit(_nearest_free)(*args))
    assert (full >= 0).sum() > 5
    for size in (int(free.sum(axis=1).max()), P):
        packed = jax.jit(_nearest_free_packed, static_argnums=7)(*args, size)
        np.testing.assert_array_equal(np.asarray(packed), full)
    for m in range(M):  # the oracle, view by view
        d = np.linalg.norm(pred[:, m, None, :] - xy[None, m], axis=-1)
        ok = track_ok[:, m, None] & free[m][None] & (det_class[m][None] == prev_class[:, None])
        want = _cheapest_first_oracle(np.where(ok & (d <= 3.0), d, np.inf))
        np.testing.assert_array_equal(full[:, m], want)


@pytest.mark.parametrize("max_gap", [0, 1])
def test_a_recording_tracked_in_parts_equals_the_whole(max_gap):
    """Parts tracked one after the other, each continuing from where the one before stopped
    (the second with fewer group rows, the third with more: the tracks carried grow), give the
    whole's groups, points and track ids."""
    from cdog_jax import associate_classes
    from cdog_jax._result import batched_association
    from cdog_jax.synthetic import default_rig, generate_skeleton_scenes
    from cdog_jax.tracking._tracks import track_part

    rig = default_rig(num_views=4)
    sk = generate_skeleton_scenes(jax.random.PRNGKey(3), rig, 2, 1.0, num_frames=7)
    mask = np.array(sk.frames.mask)
    xy, classes = np.asarray(sk.frames.xy, np.float32), np.asarray(sk.frames.class_id)
    mask[3, 1:] &= classes[3, 1:] > 8  # a frame with fewer groups: recovered by the prior
    classes = np.where(mask, classes, 0)
    result = associate_classes(rig, xy, mask, classes)
    options = dict(
        xy=xy, mask=mask, classes=classes, temporal_prior=True, max_step=None,
        max_step_px=60.0, max_err_px=None, max_gap=max_gap, min_views=2, dist=None,
    )  # fmt: skip
    whole, _ = track_part(rig, result, None, **options)
    assert whole.num_tracks > 10, whole.num_tracks
    assert np.asarray(whole.recovered).any()

    a = result.association
    rows = int(np.asarray(a.num_groups)[3])
    assert rows < a.valid.shape[1] and not np.asarray(a.valid)[3, rows:].any()

    def part(start, stop, cut):
        frame = lambda v: np.asarray(v)[start:stop]  # noqa: E731
        row = lambda v: frame(v)[:, :cut]  # noqa: E731
        fields = {
            k: frame(getattr(a, k))
            for k in ("labels", "num_groups", "sigma_px", "tau_px", "status")
        }
        fields.update(
            {
                k: row(getattr(a, k))
                for k in ("groups", "valid", "points3d", "bpe", "err_px", "n_views")
            }
        )
        return result._replace(
            association=batched_association(**fields), group_class=row(result.group_class)
        )

    state = None
    for start, stop, cut in ((0, 3, None), (3, 4, rows), (4, 7, None)):
        part_result = part(start, stop, cut)
        opts = {
            k: v[start:stop] if k in ("xy", "mask", "classes") else v for k, v in options.items()
        }
        tracked, state = track_part(rig, part_result, state, **opts)
        for f in range(stop - start):
            valid, ref = (
                np.asarray(tracked.association.valid[f]),
                np.asarray(whole.association.valid[start + f]),
            )
            np.testing.assert_array_equal(
                tracked.track_id[f][valid], whole.track_id[start + f][ref]
            )
            np.testing.assert_array_equal(
                np.asarray(tracked.association.groups[f])[valid],
                np.asarray(whole.association.groups[start + f])[ref],
            )
            np.testing.assert_array_equal(
                tracked.association.labels[f], whole.association.labels[start + f]
            )
            np.testing.assert_array_equal(
                tracked.recovered[f][valid], whole.recovered[start + f][ref]
            )
            np.testing.assert_allclose(
                np.asarray(tracked.association.points3d[f])[valid],
                np.asarray(whole.association.points3d[start + f])[ref],
                rtol=0, atol=1e-5,
            )  # fmt: skip
    assert state.rows == result.association.valid.shape[1]


@pytest.mark.parametrize("displaced", [0, 1, 2, 3])
def test_the_prior_drops_the_worst_view_until_the_rest_agree(displaced):
    # A point seen by 6 views, missed by the association in frame 1, where the first
    # `displaced` views see its detection 8 px off: the prior drops them one a round, the
    # worst first, and recovers the point from the views that agree (a search that stopped
    # after fewer rounds would keep an outlier and refuse the point).
    views = 6
    rig = ring_rig(num_views=views)
    truth = np.stack([X0 + STEP * f for f in range(2)])
    xy = np.stack([project_np(rig, truth[f])[0] for f in range(2)]).astype(np.float32)
    instance = np.broadcast_to(np.arange(2), (2, views, 2))
    mask = np.ones((2, views, 2), bool)
    result = associate_batch(rig, xy, mask, method="paper", sigma=1.0)
    missed = _without_group(result, 1, 0, instance)
    xy[1, :displaced, 0] += 8.0
    tracked = track_groups(rig, missed, xy=xy, mask=mask, temporal_prior=True, max_err_px=3.0)
    f, g = np.argwhere(np.asarray(tracked.recovered))[0]
    assert f == 1 and int(tracked.association.n_views[f, g]) == views - displaced
    kept = np.asarray(tracked.association.groups[f, g]) >= 0
    assert not kept[:displaced].any() and kept[displaced:].all()


@pytest.mark.parametrize("lost_count", [5, 33])
def test_the_prior_on_the_lost_tracks_packed_equals_it_on_every_row(lost_count):
    """The prior's search, triangulations and view dropping on the lost tracks alone,
    packed to the front (a frame losing at most ``LOST_ROWS`` of its tracks), give the table
    of the same work on every row, bit for bit under the suite's switches (no fused
    multiply-adds: tests/conftest.py): the same groups in the same free rows."""
    from cdog_jax.tracking._temporal_prior import LOST_ROWS, _recover, recover_tracks
    from cdog_jax.tracking._tracks import _Out

    rig = ring_rig(4)
    rng = np.random.default_rng(lost_count)
    T, H, P = 48, 40, 24
    M = rig.num_views
    prev_X = rng.uniform(-0.5, 0.5, (T, 3)).astype(np.float32)
    moved = prev_X + rng.normal(0, 0.01, (T, 3)).astype(np.float32)
    lost = np.zeros(T, bool)
    lost[rng.choice(T, lost_count, replace=False)] = True
    assert (lost.sum() <= LOST_ROWS) == (lost_count == 5)
    # Each view holds the moved points of some lost tracks (plus noise) and strays, shuffled.
    xy = rng.uniform(0, 640, (M, P, 2)).astype(np.float32)
    mask = rng.random((M, P)) < 0.7
    pixels, _ = project_np(rig, moved)  # (M, T, 2)
    classes = rng.integers(0, 2, T).astype(np.int32)
    det_class = rng.integers(0, 2, (M, P)).astype(np.int32)
    for m in range(M):
        for k, t in enumerate(np.flatnonzero(lost)[: P // 2]):
            if rng.random() < 0.8:
                xy[m, 2 * k] = pixels[m, t] + rng.normal(0, 0.5, 2)
                mask[m, 2 * k], det_class[m, 2 * k] = True, classes[t]
    labels = np.where(rng.random((M, P)) < 0.2, 0, -1).astype(np.int32)
    valid = np.arange(H) < 10
    out = _Out(
        np.zeros((H, 3), np.float32),
        valid,
        np.zeros(H, np.int32),
        np.full((H, M), -1, np.int32),
        np.zeros(H, np.float32),
        np.zeros(H, np.float32),
        labels,
        np.where(valid, np.arange(H), -1).astype(np.int32),
        np.zeros(H, bool),
        np.int32(0),
    )
    track = np.arange(T, dtype=np.int32) + 100
    gate = np.full(T, 40.0, np.float32)
    frame = (rig, out, xy, mask, det_class, np.float32(4.0), 2)
    packed = jax.jit(recover_tracks, static_argnums=11)(
        rig, out, prev_X, lost, classes, track, xy, mask, det_class, gate, np.float32(4.0), 2
    )
    every = jax.jit(_recover, static_argnums=6)(*frame, prev_X, lost, classes, track, gate)
    assert int(np.asarray(packed.recovered).sum()) > 0  # the test finds tracks
    for name, a, b in zip(_Out._fields, packed, every):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=name)

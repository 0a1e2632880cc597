"""associate_classes: different classes are never joined (even where their detections
coincide), every (frame, class) is associated as `associate` would on that class alone,
results keep the input's slots and carry the class in JSON, CSV and NPZ, and the
command line associates an OpenPose folder by keypoint type."""

import csv
import dataclasses
import json
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import run_with_xla_defaults

import cdog_jax
from cdog_jax import associate_classes
from cdog_jax.cli import main
from cdog_jax.io import save_association_csv, save_association_json, save_association_npz, save_rig
from cdog_jax.synthetic import DEFAULT_BOX, default_rig

F, C, K, M = 2, 3, 2, 4  # frames, classes, instances per class, views


@pytest.fixture(scope="module")
def scene():
    """Classes 0 and 1 sit at the same 3D points (their detections coincide pixel for
    pixel); slots are shuffled per view; two detections are missing."""
    rig = default_rig(num_views=M)
    rng = np.random.default_rng(0)
    lo, hi = (np.asarray(b) for b in DEFAULT_BOX)
    X = rng.uniform(lo, hi, (F, C, K, 3))
    X[:, 1] = X[:, 0]
    xy_true, _ = cdog_jax.project(rig, jnp.asarray(X.reshape(-1, 3), jnp.float32))
    xy_true = np.asarray(xy_true).reshape(M, F, C * K, 2).transpose(1, 0, 2, 3)  # (F, M, C·K, 2)
    xy_true = xy_true + rng.normal(0.0, 0.3, xy_true.shape)
    xy_true[:, :, C * 0 + 0] = xy_true[
        :, :, K
    ]  # class 1's first instance coincides exactly with class 0's
    truth = np.broadcast_to(np.arange(C * K), (F, M, C * K)).copy()  # c · K + k
    for f in range(F):
        for m in range(M):
            order = rng.permutation(C * K)
            xy_true[f, m], truth[f, m] = xy_true[f, m, order], truth[f, m, order]
    mask = np.ones((F, M, C * K), bool)
    mask[0, 2, 3] = mask[1, 0, 1] = False
    return rig, xy_true.astype(np.float32), mask, truth // K, truth


def _groups(assoc, f):
    """Valid groups of frame ``f`` as sets of ``(view, slot)``."""
    groups = np.asarray(assoc.groups[f])
    return [
        {(m, int(s)) for m, s in enumerate(g) if s >= 0} for g in groups[np.asarray(assoc.valid[f])]
    ]


def test_classes_never_joined_and_truth_recovered(scene):
    rig, xy, mask, classes, truth = scene
    out = associate_classes(rig, xy, mask, classes, class_names=["a", "b", "c"], sigma=1.0)
    a = out.association
    assert out.num_classes == C and out.class_names == ("a", "b", "c")
    for f in range(F):
        groups = _groups(a, f)
        assert len(groups) == C * K  # every point of every class, nothing joined across classes
        for g, c in zip(groups, out.group_class[f][np.asarray(a.valid[f])]):
            assert {int(classes[f, m, s]) for m, s in g} == {int(c)}
            assert len({int(truth[f, m, s]) for m, s in g}) == 1
        labels = np.asarray(a.labels[f])
        for row, g in enumerate(groups):  # labels point back at the group's row
            assert all(labels[m, s] == row for m, s in g)
        assert (labels[~mask[f]] == -1).all()


def test_each_class_as_associate_on_that_class_alone(scene):
    rig, xy, mask, classes, _ = scene
    out = associate_classes(rig, xy, mask, classes, sigma=1.0)
    a = out.association
    f, c = 1, 2
    sub_xy = np.zeros((M, K, 2), np.float32)
    sub_mask = np.zeros((M, K), bool)
    slot_of = np.full((M, K), -1)
    for m in range(M):
        slots = np.flatnonzero(mask[f, m] & (classes[f, m] == c))
        sub_xy[m, : len(slots)], sub_mask[m, : len(slots)], slot_of[m, : len(slots)] = (
            xy[f, m, slots],
            True,
            slots,
        )
    ref = cdog_jax.associate(rig, sub_xy, sub_mask, sigma=1.0)
    want = {}
    for g in range(int(ref.num_groups)):
        members = frozenset(
            (m, int(slot_of[m, s])) for m, s in enumerate(np.asarray(ref.groups[g])) if s >= 0
        )
        want[members] = np.asarray(ref.points3d[g])
    got = {}
    for g in np.flatnonzero(np.asarray(a.valid[f]) & (out.group_class[f] == c)):
        members = frozenset((m, int(s)) for m, s in enumerate(np.asarray(a.groups[f, g])) if s >= 0)
        got[members] = np.asarray(a.points3d[f, g])
    assert set(got) == set(want) and len(want) == K
    for members, X in want.items():
        np.testing.assert_allclose(got[members], X, rtol=1e-5, atol=1e-5)


def test_pooled_sigma_one_per_frame(scene):
    rig, xy, mask, classes, _ = scene
    a = associate_classes(rig, xy, mask, classes, sigma="auto").association
    sigma = np.asarray(a.sigma_px)
    assert sigma.shape == (F,) and (sigma > 0).all() and (sigma < 5).all()


@pytest.mark.parametrize("robust", [False, True], ids=["auto", "robust"])
def test_a_frame_whose_pooled_sigma_falls_back_is_flagged(scene, robust):
    """A frame with too little evidence for σ (one detection a view) gets the fallback σ and
    ``Status.SIGMA_FALLBACK``, as a scene estimating its own σ does; a frame with enough
    gets neither; pooled over both frames the fit has enough."""
    rig, xy, mask, classes, _ = scene
    method = cdog_jax.Config.best(sigma_mode="robust") if robust else None
    thin = mask.copy()
    thin[1] &= np.cumsum(mask[1], axis=1) <= 1
    a = associate_classes(rig, xy, thin, classes, method=method).association
    flagged = (np.asarray(a.status) & int(cdog_jax.Status.SIGMA_FALLBACK)) > 0
    np.testing.assert_array_equal(flagged, [False, True])
    assert np.asarray(a.sigma_px)[1] == 1.0  # the fallback σ (px)
    pooled = associate_classes(rig, xy, thin, classes, method=method, sigma_pool="all")
    assert not (np.asarray(pooled.association.status) & int(cdog_jax.Status.SIGMA_FALLBACK)).any()
    # class_sigmas gives the same σ and names the frame that fell back.
    estimator = "robust" if robust else "auto"
    with pytest.warns(UserWarning, match=r"1 of 2 frames \(first: frame 1\) fell back"):
        sigma = cdog_jax.class_sigmas(rig, xy, thin, classes, estimator=estimator)
    np.testing.assert_array_equal(sigma, np.asarray(a.sigma_px))
    cdog_jax.class_sigmas(rig, xy, thin, classes, estimator=estimator, pool="all")  # no warning


@pytest.mark.parametrize("robust", [False, True], ids=["auto", "robust"])
def test_long_recordings_fit_sigma_in_chunks_bitwise_as_in_one(scene, monkeypatch, robust):
    """A long recording's σ samples and fits run in chunks (flat memory); each frame's σ is
    bitwise the one of a single call. Chunks of 2 scenes and 1 frame row force the path."""
    import cdog_jax.people._classes as classes_module

    rig, xy, mask, classes, _ = scene
    method = cdog_jax.Config.best(sigma_mode="robust") if robust else None
    one = associate_classes(rig, xy, mask, classes, sigma="auto", method=method).association
    monkeypatch.setattr(classes_module, "SAMPLE_CHUNK", 2)
    monkeypatch.setattr(classes_module, "FIT_ELEMENTS", 1)
    chunked = associate_classes(rig, xy, mask, classes, sigma="auto", method=method).association
    np.testing.assert_array_equal(np.asarray(chunked.sigma_px), np.asarray(one.sigma_px))
    np.testing.assert_array_equal(np.asarray(chunked.labels), np.asarray(one.labels))
    np.testing.assert_array_equal(np.asarray(chunked.status), np.asarray(one.status))


def _regroup_oracle(xy, mask, classes, C, weights):
    """Scenes of (frame, class) by loops: those whose class shows in two views or more, in
    (frame, class) order; each view's detections of the class in slot order."""
    F, M, _ = mask.shape
    scenes = []
    for f in range(F):
        for c in range(C):
            cell = [np.flatnonzero(mask[f, m] & (classes[f, m] == c)) for m in range(M)]
            if sum(len(s) > 0 for s in cell) >= 2:
                scenes.append((f, c, cell))
    B, Pc = len(scenes), max([len(s) for _, _, cell in scenes for s in cell] + [1])
    out = (
        np.zeros((B, M, Pc, 2), xy.dtype),
        np.zeros((B, M, Pc), bool),
        np.full((B, M, Pc), -1, np.int64),
        np.array([f for f, _, _ in scenes], np.int64),
        np.array([c for _, c, _ in scenes], np.int64),
        None if weights is None else np.zeros((B, M, Pc), weights.dtype),
    )
    for b, (f, _, cell) in enumerate(scenes):
        for m, slots in enumerate(cell):
            n = len(slots)
            out[0][b, m, :n], out[1][b, m, :n], out[2][b, m, :n] = xy[f, m, slots], True, slots
            if weights is not None:
                out[5][b, m, :n] = weights[f, m, slots]
    return out


def test_class_scenes_are_the_loops_scenes():
    """The class scenes of a batch of frames, as loops over frames, classes and views make
    them (random frames, weights, empty ones)."""
    import cdog_jax.people._classes as classes_module

    rng = np.random.default_rng(0)
    for _ in range(200):
        F, M, P, C = (int(rng.integers(1, n)) for n in (4, 6, 9, 5))
        mask = rng.random((F, M, P)) < rng.random()
        classes_ = rng.integers(0, C, (F, M, P))
        xy = rng.random((F, M, P, 2)).astype(np.float32)
        weights = rng.random((F, M, P)) if rng.random() < 0.5 else None
        got = classes_module._regroup(xy, mask, classes_, C, weights)
        want = _regroup_oracle(xy, mask, classes_, C, weights)
        for name, a, b in zip(got._fields, got, want):
            if b is None:
                assert a is None, name
                continue
            assert a.dtype == b.dtype and a.shape == b.shape, name
            np.testing.assert_array_equal(a, b, err_msg=name)


def test_a_frame_queued_behind_its_sigma_fit_is_the_frame_alone(scene, monkeypatch):
    """One frame with a σ table floor (a live frame): σ stays on the device and the
    association is queued behind its fit (nothing read back between them); every field is
    bitwise the frame's through the two σ programs and the host, with and without the
    person vote, and a frame whose σ falls back is flagged as there. (The estimators' fits
    agree bitwise in one program and in two: the test above.)"""
    import cdog_jax.people._classes as classes_module

    rig, xy, mask, classes, truth = scene
    shared = []
    batch, at = classes_module.associate_batch_at, classes_module.associate_classes_at

    def spy(*args, shared_sigma=None, **kwargs):
        shared.append(isinstance(shared_sigma, jax.Array))
        return batch(*args, shared_sigma=shared_sigma, **kwargs)

    monkeypatch.setattr(classes_module, "associate_batch_at", spy)
    # Noise of 60 px: σ̂ above 1 % of the focal length, so σ falls back (the same shapes).
    noisy = xy + np.random.default_rng(1).normal(0.0, 60.0, xy.shape).astype(xy.dtype)
    fallback = int(cdog_jax.Status.SIGMA_FALLBACK)
    for points, options in ((xy, {}), (noisy, {}), (xy, {"instances": truth[:1] % K})):
        frame = (points[:1], mask[:1], classes[:1])
        alone = at(rig, *frame, min_slots=4, **options).association  # one program's shapes
        queued = at(rig, *frame, min_slots=4, min_samples=16, **options).association
        assert shared[-2:] == [False, True]
        for field in dataclasses.fields(alone):
            a, b = (np.asarray(getattr(x, field.name)) for x in (alone, queued))
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), field.name
        assert bool(np.asarray(queued.status)[0] & fallback) == (points is noisy)


@pytest.mark.parametrize("vote", [False, True], ids=["plain", "person-vote"])
def test_results_read_on_the_host_are_the_results(scene, vote):
    """``on_host`` (a caller that reads the association there, as the live loop does)
    changes where the arrays are and nothing else: NumPy arrays of the same values, also
    after the person vote and for frames with no detection at all."""
    from cdog_jax.people._classes import associate_classes_at

    rig, xy, mask, classes, truth = scene
    options = {"instances": truth % K} if vote else {}
    for m in (mask, np.zeros_like(mask)):
        device = associate_classes_at(rig, xy, m, classes, **options).association
        host = associate_classes_at(rig, xy, m, classes, on_host=True, **options).association
        for d, h in zip(jax.tree.leaves(device), jax.tree.leaves(host)):
            assert isinstance(d, jax.Array) and type(h) is np.ndarray
            np.testing.assert_array_equal(np.asarray(d), h)


def test_bad_classes_refused(scene):
    rig, xy, mask, classes, _ = scene
    bad = classes.copy()
    bad[1, 2, 0] = -3
    with pytest.raises(
        ValueError,
        match="classes must be >= 0 where mask is True; got -3 at frame 1, view 2, slot 0",
    ):
        associate_classes(rig, xy, mask, bad)
    with pytest.raises(ValueError, match="class id 2 at frame 0, .* is >= num_classes = 2"):
        associate_classes(rig, xy, mask, classes, num_classes=2)
    with pytest.raises(ValueError, match=f"min_views must be at most the number of views, {M} "):
        associate_classes(rig, xy, mask, classes, min_views=M + 1)


def test_results_carry_the_class(scene, tmp_path):
    rig, xy, mask, classes, _ = scene
    out = associate_classes(rig, xy, mask, classes, class_names=["a", "b", "c"], sigma=1.0)
    save_association_json(tmp_path / "r.json", out, xy, mask, classes=classes)
    data = json.loads((tmp_path / "r.json").read_text())
    assert data["class_names"] == ["a", "b", "c"]
    for f, frame in enumerate(data["frames"]):
        for g in frame["groups"]:
            assert g["class_name"] == "abc"[g["class"]]
            assert {int(classes[f, r[0], r[1]]) for r in g["members"]} == {g["class"]}
        assert len(frame["unassigned_classes"]) == len(frame["unassigned"])
    save_association_csv(tmp_path / "r.csv", out)
    with open(tmp_path / "r.csv") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert len(rows) == int(np.asarray(out.association.num_groups).sum())
    assert all(r["class_name"] == "abc"[int(r["class"])] for r in rows)
    save_association_npz(tmp_path / "r.npz", out, classes=classes)
    with np.load(tmp_path / "r.npz") as z:
        np.testing.assert_array_equal(z["group_class"], out.group_class)
        assert z["class_names"].tolist() == ["a", "b", "c"] and z["classes"].shape == classes.shape


def test_cli_associates_openpose_folder_by_keypoint(scene, tmp_path, capsys):
    rig, xy, mask, classes, truth = scene
    save_rig(tmp_path / "rig.json", rig, format="json")
    # One OpenPose person per instance k; keypoint j = class; the person order differs per view.
    for m in range(M):
        os.makedirs(tmp_path / "pose" / f"cam{m + 1}")
        for f in range(F):
            people = np.zeros((K, C, 3))
            for s in np.flatnonzero(mask[f, m]):
                c, k = divmod(int(truth[f, m, s]), K)
                people[(k + m) % K, c] = [*xy[f, m, s], 0.9]
            with open(tmp_path / "pose" / f"cam{m + 1}" / f"f.{f:04d}.json", "w") as fh:
                json.dump(
                    {"people": [{"pose_keypoints_2d": p.reshape(-1).tolist()} for p in people]}, fh
                )
    out = tmp_path / "out.csv"
    code = main(
        [
            "associate",
            "--rig",
            str(tmp_path / "rig.json"),
            "--points",
            str(tmp_path / "pose"),
            "--sigma",
            "1",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "classes: 3" in text
    with open(out) as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert len(rows) == F * C * K
    assert sorted(int(r["class"]) for r in rows if r["frame"] == "0") == [0, 0, 1, 1, 2, 2]


def test_cli_keypoint_options_checked_before_work(scene, tmp_path, capsys):
    rig, *_ = scene
    save_rig(tmp_path / "rig.json", rig, format="json")
    points = tmp_path / "points.json"
    points.write_text(json.dumps({"views": [[[1, 2]], [[3, 4]], [[5, 6]], [[7, 8]]]}))
    code = main(
        [
            "associate",
            "--rig",
            str(tmp_path / "rig.json"),
            "--points",
            str(points),
            "--keypoints",
            "BODY_25",
        ]
    )
    assert code == 2
    assert "--keypoints names OpenPose keypoints" in capsys.readouterr().err
    os.makedirs(tmp_path / "pose" / "cam1")
    code = main(
        ["associate", "--rig", str(tmp_path / "rig.json"), "--points", str(tmp_path / "pose")]
    )
    assert code == 2
    assert "expected one folder per camera" in capsys.readouterr().err


def test_associate_traced_with_classes_never_joins_two_classes():
    """``associate_traced(..., classes=)`` (one graph of every class): classes that agree
    with the true points change nothing; classes drawn at random split every group into
    single-class ones."""
    from helpers import random_scene, ring_rig

    rig = ring_rig(3)
    xy, mask, instance, _ = random_scene(rig, 4, 6, sigma=0.2, seed=1)
    config = cdog_jax.Config.paper()
    thresholds = config.thresholds(0.2)
    run = jax.jit(cdog_jax.associate_traced, static_argnums=4)
    plain = cdog_jax.associate(
        rig, xy.astype(np.float32), mask, method=config, thresholds=thresholds
    )  # a program other tests compile
    agreeing = run(
        rig,
        jnp.asarray(xy, jnp.float32),
        jnp.asarray(mask),
        thresholds,
        config,
        classes=jnp.asarray(instance % 2, jnp.int32),
    )
    np.testing.assert_array_equal(np.asarray(plain.labels), np.asarray(agreeing.labels))
    random_classes = np.random.default_rng(2).integers(0, 2, instance.shape).astype(np.int32)
    split = run(
        rig,
        jnp.asarray(xy, jnp.float32),
        jnp.asarray(mask),
        thresholds,
        config,
        classes=jnp.asarray(random_classes),
    )
    groups, valid = np.asarray(split.groups), np.asarray(split.valid)
    assert valid.sum() > 0
    for g in np.flatnonzero(valid):
        views = np.flatnonzero(groups[g] >= 0)
        assert len(set(random_classes[views, groups[g, views]].tolist())) == 1


def one_program_sigma_is_the_two_programs():
    """A frame's pooled σ fitted in one program (the samples, their table and the fit: a
    live frame's) is bitwise the σ and fallback of the samples' program and the fit's with
    the table made on the host: both estimators, with a lens, and a frame whose σ falls
    back; the samples' bound is the used count where no epipolar line is degenerate."""
    from cdog_jax.people import _classes as classes

    rig = default_rig(num_views=5)
    rng = np.random.default_rng(3)
    C, K = 6, 3  # classes, people
    lo, hi = (np.asarray(b) for b in DEFAULT_BOX)
    xy, _ = cdog_jax.project(rig, jnp.asarray(rng.uniform(lo, hi, (C * K, 3)), jnp.float32))
    xy = np.asarray(xy)[None]  # (1, M, C·K, 2)
    xy = (xy + rng.standard_t(3, xy.shape) * 2.0).astype(np.float32)
    classes_ = np.broadcast_to(np.arange(C * K) // K, (1, 5, C * K)).copy()
    mask = rng.random((1, 5, C * K)) > 0.2
    mask[:, :, :K] &= np.arange(5)[None, :, None] == 1  # class 0: one view only
    sparse = np.zeros_like(mask)
    sparse[:, :2, K] = True  # one point of class 1 in two views: σ falls back
    # View 0 without the last two classes: 185 samples at most, a table of 192 entries (one
    # and a half times the floor of 128) whose sums are 256 wide.
    mask[0, 0, -2 * K :] = False
    dist = np.array([[-0.1, 0.01, 0.0, 0.0, 0.0]] * 5, np.float32)
    widths = set()  # the one-program table's width less its sums'
    for m, estimator, lens, falls_back in (
        (mask, "auto", None, False),
        (sparse, "auto", None, True),
        (mask, "robust", dist, False),
    ):
        scenes = classes._at_least(classes._regroup(xy, m, classes_, C, None), 8, 8)
        if lens is None:
            used = classes._chunked_samples(rig, scenes, None, np.float32, False).per_scene
            assert classes._sample_bound(scenes.mask) == used.sum()
        two = classes._pooled_sigma(rig, scenes, 1, lens, np.float32, "frame", estimator)
        one = classes._one_table_fit(rig, scenes, lens, np.float32, estimator == "robust", 128)
        for a, b in zip((np.asarray(a)[:1] for a in one), two):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), estimator
        assert two[1].all() == falls_back, estimator
        width = classes.live_fit_width(classes._sample_bound(scenes.mask) + 1, 128)
        widths.add(width - classes.fit_width(width))
    assert widths == {-64, 0}  # tables narrower than their sums (a power of two) and not


def test_one_program_sigma_is_the_two_programs_bitwise():
    """Under XLA's defaults (the code users run)."""
    run_with_xla_defaults(__file__, "one_program_sigma_is_the_two_programs")

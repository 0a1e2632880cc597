"""The person-level vote (associate_classes(..., instances=, person_vote=)): a joint group
that geometry alone swaps between two people is put right by the skeletons' per-view
instance index, the clustering of (view, instance) nodes matches a brute-force optimum on
tiny cases, and bad instance arguments are refused before any work."""

import itertools

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import cdog_jax
from cdog_jax import PersonVote, associate_classes
from cdog_jax.people._persons import (
    _camera,
    cluster_people,
    consistent_groups,
    person_nodes,
    vote_matrix,
)
from cdog_jax.synthetic import default_rig

M, J = 3, 3  # views, joint classes
# The per-view instance index of person A and B (a 2D detector's order, not an identity).
INSTANCE = np.array([[0, 1], [1, 0], [0, 1]])


@pytest.fixture(scope="module")
def swapped():
    """Two people, three joints each. Joint 2 of B sits 0.4 units behind A's on view 2's
    ray (and 3 px aside): in views 0 and 1 the two are far apart, in view 2 within the
    noise. View 2's joint-2 detections carry the skeletons' instances crosswise to the
    pixels: the one labelled A is where B projects and vice versa (the 2D detector put
    them in the skeleton it saw; the geometry of view 2 cannot tell). Slots: ``person · J + joint``."""
    rig = default_rig(num_views=M)
    R, t = np.asarray(rig.R, np.float64), np.asarray(rig.t, np.float64)
    centre2 = -R[2].T @ t[2]
    joints_a = np.array([[-0.6, -0.3, 0.3], [-0.6, 0.3, 0.2], [0.0, 0.0, 0.0]])
    ray = -centre2 / np.linalg.norm(centre2)
    aside = np.cross(ray, [0.0, 0.0, 1.0])
    joint2_b = joints_a[2] + 0.4 * ray + 0.006 * aside / np.linalg.norm(aside)
    joints_b = np.array([[0.6, 0.3, 0.3], [0.6, -0.3, 0.2], joint2_b])
    X = np.concatenate([joints_a, joints_b])  # (2·J, 3), point id person · J + joint
    xy, _ = cdog_jax.project(rig, jnp.asarray(X, jnp.float32))
    xy = np.array(xy)  # (M, 2·J, 2)
    xy[2, [2, J + 2]] = xy[2, [J + 2, 2]]  # view 2: A's joint-2 slot holds B's pixel and vice versa
    mask = np.ones((1, M, 2 * J), bool)
    classes = np.broadcast_to(np.arange(2 * J) % J, (1, M, 2 * J))
    person = np.arange(2 * J) // J
    instances = INSTANCE[:, person][None]  # (1, M, 2·J)
    return rig, xy[None].astype(np.float32), mask, classes, instances, person


def _people_in_groups(assoc, person):
    """The set of people (by slot) of every valid group of frame 0."""
    groups = np.asarray(assoc.groups[0])[np.asarray(assoc.valid[0])]
    return [{int(person[s]) for s in g if s >= 0} for g in groups]


def test_vote_puts_a_swapped_joint_group_right(swapped):
    rig, xy, mask, classes, instances, person = swapped
    plain = associate_classes(rig, xy, mask, classes, sigma=2.0, method="paper")
    mixed = [p for p in _people_in_groups(plain.association, person) if len(p) > 1]
    assert len(mixed) == 2  # geometry alone: both joint-2 groups join A and B
    voted = associate_classes(
        rig, xy, mask, classes, sigma=2.0, method="paper", instances=instances, person_vote=True
    )
    a = voted.association
    people = _people_in_groups(a, person)
    assert all(len(p) == 1 for p in people) and len(people) == 2 * J
    assert np.all(np.asarray(a.n_views[0])[np.asarray(a.valid[0])] == M)
    assert sorted(voted.group_class[0][voted.group_class[0] >= 0].tolist()) == sorted(
        list(range(J)) * 2
    )
    # Every detection labelled, labels and groups agree, points re-triangulated from the new members.
    labels, groups = np.asarray(a.labels[0]), np.asarray(a.groups[0])
    assert np.all(labels >= 0)
    for m in range(M):
        for s in range(2 * J):
            assert groups[labels[m, s], m] == s
    assert np.all(np.asarray(a.err_px[0])[np.asarray(a.valid[0])] < 4.0)
    # On by default with instances; person_vote=False: the plain result.
    default = associate_classes(
        rig, xy, mask, classes, sigma=2.0, method="paper", instances=instances
    )
    np.testing.assert_array_equal(np.asarray(default.association.labels), np.asarray(a.labels))
    off = associate_classes(
        rig, xy, mask, classes, sigma=2.0, method="paper", instances=instances, person_vote=False
    )
    np.testing.assert_array_equal(
        np.asarray(off.association.labels), np.asarray(plain.association.labels)
    )


class _Flat:
    """The camera of :func:`_crossed`: view m sees a point of height z at
    ``(100 + scale[m] · z, 0)`` px; its DLT reads the height from view 0's pixel. The rows
    it triangulates are kept in ``triangulated`` (each row's view-0 slot)."""

    scale = np.array([400.0, 400.0, 4.0])

    def __init__(self):
        self.triangulated = []

    def __call__(self, X):
        return np.stack(np.broadcast_arrays(100.0 + self.scale[None, :] * X[:, 2:3], 0.0), axis=-1)

    def triangulate(self, xy_, rows):
        self.triangulated.extend(int(r[0]) for r in rows)
        return np.array([[0.0, 0.0, (xy_[0, r[0], 0] - 100.0) / self.scale[0]] for r in rows])


def _crossed():
    """A hand-made group table (no pipeline) seen by :class:`_Flat`'s camera: person A at
    z = 0, B at z = 1, 4 px apart in view 2 only. There, A's joint-2 detection sits at B's
    pixel and is in B's group, and B's in A's. Returns ``groups, classes, instances, xy,
    points`` (the points of the groups as drawn)."""
    height = np.arange(2 * J) // J  # the person of every slot is its height
    xy = np.stack(
        np.broadcast_arrays(100.0 + _Flat.scale[:, None] * height[None, :], 0.0), axis=-1
    )  # (M, 2·J, 2)
    xy[2, [2, J + 2]] = xy[2, [J + 2, 2]]
    classes = np.broadcast_to(np.arange(2 * J) % J, (M, 2 * J))
    groups = np.array([[s] * M for s in range(2 * J)])
    groups[2, 2], groups[J + 2, 2] = J + 2, 2  # the geometric (crossed) groups
    points = np.array([[0.0, 0.0, float(z)] for z in height])
    return groups, classes, INSTANCE[:, height], xy, points


def test_consistent_groups_reattaches_within_the_gate_only():
    """The crossed groups of :func:`_crossed`: within the gate (5 px) the two joints change
    groups; within 1 px they are only detached."""
    groups, classes, instances, xy, points = _crossed()
    valid = np.ones(2 * J, bool)
    gclass = np.arange(2 * J) % J
    fixed = consistent_groups(
        groups, valid, gclass, classes, instances, xy, points, _Flat(), 5.0, PersonVote(), 2
    )
    assert fixed.groups[2, 2] == 2 and fixed.groups[J + 2, 2] == J + 2
    assert fixed.changed.tolist() == [s % J == 2 for s in range(2 * J)] and fixed.valid.all()
    tight = consistent_groups(
        groups, valid, gclass, classes, instances, xy, points, _Flat(), 1.0, PersonVote(), 2
    )
    assert tight.groups[2, 2] == -1 and tight.groups[J + 2, 2] == -1  # detached, beyond the gate
    assert tight.valid.all() and len(tight.valid) == 2 * J
    np.testing.assert_array_equal(
        np.delete(tight.groups, [2, J + 2], axis=0), np.delete(groups, [2, J + 2], axis=0)
    )
    unknown = consistent_groups(
        groups,
        valid,
        gclass,
        classes,
        np.full_like(instances, -1),
        xy,
        points,
        _Flat(),
        5.0,
        PersonVote(),
        2,
    )
    np.testing.assert_array_equal(unknown.groups, groups)  # no instance known: nothing moves
    assert not unknown.changed.any()


def test_the_gate_reads_a_changed_groups_point_triangulated_again():
    """The crossed groups of :func:`_crossed`, their points as the association left them,
    pulled 3 units up by the foreign member (12 px off in view 2, beyond the 5 px gate): each
    detached joint is measured against its own person's group re-triangulated without that
    member (4 px) and joins it. Only those two groups, the ones a detached joint may join,
    are triangulated again."""
    groups, classes, instances, xy, drawn = _crossed()

    def vote(groups, points):  # the vote at a 5 px gate, and the rows it triangulated
        camera = _Flat()
        valid, gclass = np.ones(2 * J, bool), np.arange(2 * J) % J
        out = consistent_groups(
            groups, valid, gclass, classes, instances, xy, points, camera, 5.0, PersonVote(), 2
        )
        return out, camera.triangulated

    pulled = drawn.copy()
    pulled[[2, J + 2], 2] += 3.0  # the association's points of the two crossed groups
    fixed, triangulated = vote(groups, pulled)
    assert fixed.groups[2, 2] == 2 and fixed.groups[J + 2, 2] == J + 2
    assert sorted(triangulated) == [2, J + 2]
    # Only A's joint crossed (A's group has no view-2 member): B's group changes, but no
    # detached joint may join it, so nothing is triangulated again; A's joint joins A's
    # group at its point as drawn.
    groups[2, 2] = -1
    one, triangulated = vote(groups, drawn)
    assert one.groups[2, 2] == 2 and one.groups[J + 2, 2] == -1
    assert one.changed[[2, J + 2]].all() and triangulated == []


def test_a_group_of_two_weakly_linked_nodes_is_kept():
    """A person seen in views 0 and 1 with a single joint group: its two nodes get one
    vote, too few to merge, but they share no view, so nothing says they are two people:
    the group stays (it would be dissolved, both joints lost, if any two persons clashed)."""
    instances = np.array(
        [[0, 1], [0, 1], [0, -1]]
    )  # person A: instance 0 everywhere; C: instance 1 in views 0, 1
    classes = np.array([[0, 1], [0, 1], [0, 0]])
    groups = np.array([[0, 0, 0], [1, 1, -1]])  # A's joint 0 in three views, C's joint 1 in two
    xy = np.zeros((M, 2, 2))
    points = np.zeros((2, 3))

    class Still:
        def __call__(self, X):
            return np.zeros((len(X), M, 2))

        def triangulate(self, xy_, rows):
            return np.zeros((len(rows), 3))

    out = consistent_groups(
        groups,
        np.ones(2, bool),
        np.array([0, 1]),
        classes,
        instances,
        xy,
        points,
        Still(),
        5.0,
        PersonVote(),
        2,
    )
    np.testing.assert_array_equal(out.groups, groups)
    assert out.valid.all() and not out.changed.any()


def _brute_force_people(votes, node_view, min_votes):
    """The view-unique partition of the nodes maximising Σ over node pairs in one cluster
    of ``votes − (min_votes − ½)`` (every pair, linked or not)."""
    best, best_score = None, -np.inf

    def partitions(items):
        if not items:
            yield []
            return
        first, rest = items[0], items[1:]
        for part in partitions(rest):
            for k in range(len(part)):
                yield part[:k] + [[first] + part[k]] + part[k + 1 :]
            yield [[first]] + part

    for part in partitions(list(range(len(node_view)))):
        if any(len({int(node_view[n]) for n in c}) < len(c) for c in part):
            continue
        score = sum(
            votes[a, b] - (min_votes - 0.5) for c in part for a, b in itertools.combinations(c, 2)
        )
        if score > best_score:
            best, best_score = part, score
    label = np.full(len(node_view), -1)
    for c in best:
        label[c] = min(c)
    return label


@settings(max_examples=25, deadline=None)
@given(st.data())
def test_clustering_matches_brute_force(data):
    """Planted people (each with at most one node per view) linked by 2–8 votes per node
    pair, with 0–1 stray votes elsewhere: the greedy clustering finds the brute-force optimum."""
    N = data.draw(st.integers(1, 7))
    node_view = np.array(data.draw(st.lists(st.integers(0, 2), min_size=N, max_size=N)))
    people = data.draw(st.lists(st.integers(0, 2), min_size=N, max_size=N))
    for n in range(
        N
    ):  # view-uniqueness of the plant: a repeated (person, view) gets a person of its own
        if any(people[k] == people[n] and node_view[k] == node_view[n] for k in range(n)):
            people[n] = 3 + n
    votes = np.zeros((N, N), np.int64)
    for a, b in itertools.combinations(range(N), 2):
        same = people[a] == people[b]
        votes[a, b] = votes[b, a] = data.draw(st.integers(2, 8) if same else st.integers(0, 1))
    got = cluster_people(votes, node_view, 2)
    np.testing.assert_array_equal(got, _brute_force_people(votes, node_view, 2))


def _table_people(votes, node_view, min_votes):
    """Greedy average linkage as a table: each step the argmax of every allowed pair's mean
    (upper triangle, row-major: ties to the first pair), the whole table computed again."""
    N = len(node_view)
    W, size = votes.astype(np.float64), np.ones(N)
    views = np.eye(int(node_view.max()) + 1 if N else 1, dtype=bool)[node_view]
    label, alive = np.arange(N), np.ones(N, bool)
    while True:
        mean = W / (size[:, None] * size[None, :])
        allowed = np.triu(np.ones((N, N), bool), 1) & alive[:, None] & alive[None, :]
        allowed &= ~(views.astype(int) @ views.T.astype(int)).astype(bool)
        score = np.where(allowed & (mean >= min_votes), mean, -1.0)
        if not N or score.max() < 0:
            return label
        a, b = divmod(int(np.argmax(score)), N)
        W[a] += W[b]
        W[:, a] += W[:, b]
        W[b], W[:, b] = 0.0, 0.0
        views[a] |= views[b]
        size[a] += size[b]
        alive[b] = False
        label[label == b] = a


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_clustering_is_the_table_argmax(data):
    """Any votes (ties, clusters of unequal sizes, fractional and zero thresholds): the
    clustering merges as an argmax over the whole table of means would, step by step."""
    N = data.draw(st.integers(0, 12))
    node_view = np.array(data.draw(st.lists(st.integers(0, 3), min_size=N, max_size=N)), int)
    half = np.array(data.draw(st.lists(st.integers(0, 4), min_size=N * N, max_size=N * N)))
    votes = np.triu(half.reshape(N, N).astype(np.int64), 1)
    votes = votes + votes.T
    min_votes = data.draw(st.sampled_from([0, 1, 2, 2.5]))
    got = cluster_people(votes, node_view, min_votes)
    np.testing.assert_array_equal(got, _table_people(votes, node_view, min_votes))


def test_the_kept_camera_is_the_rigs_own():
    """The vote's host projection is kept for the rig a loop passes frame after frame, and
    made again for another rig object (even an equal one) or another table size."""
    rig, other = default_rig(num_views=3), default_rig(num_views=4)
    first = _camera(rig, 8)
    assert _camera(rig, 8) is first
    assert _camera(other, 8).rig is other
    np.testing.assert_array_equal(_camera(other, 8).P, other.host_proj())
    again = _camera(rig, 8)
    assert again is not first and again.rig is rig
    assert _camera(rig, 16).min_rows == 16
    equal = default_rig(num_views=3)
    assert _camera(equal, 16).rig is equal


def test_a_rig_of_numpy_cameras_is_read_every_call():
    """NumPy cameras can change in place between two calls with the same rig object: the
    vote's host projection is then made from what they hold now, never kept."""
    base = default_rig(num_views=3)
    # As a rig built from NumPy arrays outside the suite's type checks holds them.
    fields = lambda r: (r.K, r.R, r.t)  # noqa: E731
    rig = eqx.tree_at(fields, base, tuple(np.array(a) for a in fields(base)))
    before = _camera(rig, 8).P.copy()
    rig.t[0, 0] += 1.0  # moved in place: the same rig object
    after = _camera(rig, 8)
    np.testing.assert_array_equal(after.P, rig.host_proj())
    assert not np.array_equal(after.P, before)


def test_nodes_and_votes():
    instances = np.array([[0, 7], [7, 0], [0, -1]])  # any ints as indices; -1 unknown
    node, node_view = person_nodes(instances)
    assert node.tolist() == [[0, 1], [3, 2], [4, -1]] and node_view.tolist() == [0, 0, 1, 1, 2]
    groups = np.array([[0, 1, -1], [1, 0, 0], [0, 0, 0]])
    votes = vote_matrix(groups, np.array([True, True, False]), node)
    assert votes[0, 2] == votes[2, 0] == 1  # group 0: (v0, 0)–(v1, 0)
    assert votes[1, 3] == votes[1, 4] == votes[3, 4] == 1  # group 1: (v0, 7), (v1, 7), (v2, 0)
    assert votes.sum() == 2 * 4  # 1 + 3 pairs, both directions; group 2 is not valid


@pytest.mark.parametrize(
    "instances, person_vote, message",
    [
        (None, True, "person_vote needs instances="),
        (np.zeros((1, M, 2)), True, "instances must have the shape of mask"),
        (np.zeros((1, M, 2 * J), np.float32), True, "dtype float32"),
        (np.full((1, M, 2 * J), -2), True, "got -2 at frame 0, view 0, slot 0"),
        (np.zeros((1, M, 2 * J), int), "yes", "person_vote must be a bool or a PersonVote"),
    ],
)
def test_bad_instances_refused(swapped, instances, person_vote, message):
    rig, xy, mask, classes, _, _ = swapped
    with pytest.raises(ValueError, match=message):
        associate_classes(
            rig,
            xy,
            mask,
            classes,
            sigma=2.0,
            method="paper",
            instances=instances,
            person_vote=person_vote,
        )


def test_person_vote_numbers_checked():
    with pytest.raises(ValueError, match="min_votes"):
        PersonVote(min_votes=0)
    with pytest.raises(ValueError, match="gate"):
        PersonVote(gate=-1.0)


def test_cli_person_vote_reads_the_instance_column(swapped, tmp_path, capsys):
    from cdog_jax.cli import main
    from cdog_jax.io import save_rig

    rig, xy, mask, classes, instances, person = swapped
    save_rig(tmp_path / "rig.json", rig, format="json")
    table = tmp_path / "points.csv"
    rows = [
        f"0,{m},{classes[0, m, s]},{float(xy[0, m, s, 0])!r},{float(xy[0, m, s, 1])!r},1,{instances[0, m, s]}"
        for m in range(M)
        for s in range(2 * J)
    ]
    table.write_text("frame,view,class,x,y,score,instance\n" + "\n".join(rows) + "\n")
    out = tmp_path / "out.npz"
    args = [
        "associate",
        "--rig",
        str(tmp_path / "rig.json"),
        "--points",
        str(table),
        "--sigma",
        "2",
        "--method",
        "paper",
        "--out",
        str(out),
    ]
    assert main(args + ["--person-vote"]) == 0
    with np.load(out) as z:
        groups, valid = z["groups"][0], z["valid"][0]
    assert (
        all(len({int(person[s]) for s in g if s >= 0}) == 1 for g in groups[valid])
        and valid.sum() == 2 * J
    )
    assert main(args) == 0  # on by default when the detections carry the person index
    with np.load(out) as z:
        np.testing.assert_array_equal(z["groups"][0], groups)
    assert main(args + ["--no-person-vote"]) == 0
    with np.load(out) as z:
        off = z["groups"][0][z["valid"][0]]
    assert any(len({int(person[s]) for s in g if s >= 0}) > 1 for g in off)
    plain = tmp_path / "plain.csv"
    plain.write_text("frame,view,class,x,y\n" + "\n".join(r.rsplit(",", 2)[0] for r in rows) + "\n")
    capsys.readouterr()
    assert (
        main(
            [
                "associate",
                "--rig",
                str(tmp_path / "rig.json"),
                "--points",
                str(plain),
                "--person-vote",
            ]
        )
        == 2
    )
    assert "--person-vote: the detections carry no per-view person index" in capsys.readouterr().err


def test_the_votes_dlt_runs_one_program_at_a_live_loops_rows():
    """A live loop gives its group capacity as the DLT table's least rows and compiles that
    table first: a later frame that re-triangulates 3 or 20 groups lowers no program (the
    rows of a power of two ≥ 8 each would be one more)."""
    import jax

    from cdog_jax.people._persons import _Camera, warm_retriangulation

    rig = default_rig(num_views=M)
    xy = np.random.default_rng(0).uniform(100, 400, (M, 24, 2))
    warm_retriangulation(rig, 40)
    lowered = []
    listener = lambda name, secs, **kw: lowered.append(name)  # noqa: E731
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        camera = _Camera(rig, 40)
        for K in (3, 20):
            rows = np.tile(np.arange(K)[:, None], (1, M))
            X = camera.triangulate(xy, rows)
            assert X.shape == (K, 3) and np.isfinite(X).all()
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert "/jax/core/compile/jaxpr_to_mlir_module_duration" not in lowered

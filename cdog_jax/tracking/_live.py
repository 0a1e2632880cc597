"""Frame by frame: an object made once for a rig that associates, triangulates and tracks each
frame as it arrives (docs/LIVE.md).

Each frame runs the same compiled programs as the offline functions: the classes'
association (:func:`cdog_jax.associate_classes`, every class one small scene; without
classes, the whole frame one scene) and one step of the tracker's ``lax.scan``
(:func:`cdog_jax.track_groups`), whose carried state (the tracks, their last points and
ages, the next id) the object holds. The frame's shapes are padded to capacities the
object keeps (slots per view and per class, scenes, group rows), so that every frame that
fits meets programs already compiled; a frame that does not fit raises a capacity to the
next rung of the shape ladder, compiles once for it and says so (a warning).
"""

from __future__ import annotations

import warnings
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._expect import expect_args
from .._method import method_argument
from .._runtime.shapes import ladder_rung, slot_capacity
from .._status import Status
from .._validate import as_array, check_observations, check_rig
from ..geometry._camera import Rig
from ..geometry._distortion import as_lens, undistorted_frames
from ..people._classes import (
    SceneResults,
    associate_classes_at,
    fit_width,
    frame_fields,
    given_classes,
    sigma_fit_widths,
    vote_on_scenes,
    warm_sigma_fits,
)
from ..people._persons import (
    PersonLinker,
    PersonVote,
    people_of_frame,
    person_vote_argument,
    warm_retriangulation,
)
from ._tracks import (
    DEFAULT_MAX_STEP_PX,
    _check_gate,
    grown_tracks,
    initial_tracks,
    track_one,
    track_scenes,
    tracking_frames,
)

DEFAULT_SLOTS = 8
"""Detections of one class in one view that the first compiled programs hold (a person
detector's joints: one per person in view)."""


class LiveFrame(NamedTuple):
    """One frame's answer from :meth:`LiveAssociator.update`, in NumPy arrays; ``G`` is the
    number of groups found in the frame (every row is a group).

    Attributes:
        frame: the frame's index in the stream (0, 1, …).
        labels: ``(M, P)`` int32 group of every detection in the input's slots, ``-1`` if
            unassigned or padding.
        groups: ``(G, M)`` int32 slot of every group's detection in each view, ``-1``.
        points3d: ``(G, 3)`` triangulated points, scene units.
        err_px: ``(G,)`` mean reprojection distance of the members (px).
        n_views: ``(G,)`` int32 views of every group.
        track_id: ``(G,)`` int32 track of every group (kept while it is seen; ids start at 0
            and are never reused).
        recovered: ``(G,)`` bool, found by the temporal prior rather than the association.
        group_class: ``(G,)`` int32 class of every group, or ``None`` without classes.
        sigma_px: the frame's noise σ (px), given or estimated.
        tau_px: the frame's epipolar gate (px).
        status: int bit flags of :class:`cdog_jax.Status` (0: nothing to report).
        person_id: ``(G,)`` int32 person of every group (``-1``: none), kept over frames
            through the tracks (as :func:`cdog_jax.identify_people`); ``None`` unless the
            frame's ``instances`` were given to an associator with classes.
        merged_people, split_people: the ids of the frame's people flagged as two merged
            into one, or as one split in two (:class:`cdog_jax.People`).
    """

    frame: int
    labels: np.ndarray
    groups: np.ndarray
    points3d: np.ndarray
    err_px: np.ndarray
    n_views: np.ndarray
    track_id: np.ndarray
    recovered: np.ndarray
    group_class: np.ndarray | None
    sigma_px: float
    tau_px: float
    status: int
    person_id: np.ndarray | None = None
    merged_people: tuple[int, ...] = ()
    split_people: tuple[int, ...] = ()


class LiveAssociator:
    """Associate, triangulate and track one frame at a time with the same answers as the
    offline :func:`cdog_jax.associate_sequence` on the same frames.

    Args:
        rig: the ``M`` cameras.
        num_classes, class_names: the detections' classes (keypoint types, marker colours):
            ``C`` class ids, or their names; neither: the detections carry no class.
        method, sigma, dist, min_views, person_vote: as in :func:`cdog_jax.associate_classes`
            (``sigma="auto"``: estimated in every frame from that frame). ``sigma="held"``:
            estimated as with ``"auto"`` until a frame's estimate is trusted (a frame with
            detections, no ``Status.SIGMA_FALLBACK``), then that σ for every later frame
            (a quarter less time a frame); :attr:`held_sigma` holds it, :meth:`reset`
            forgets it.
        temporal_prior: recover a track missed in a frame from that frame's unassigned
            detections (default on, as in :func:`cdog_jax.associate_sequence`).
        max_step, max_step_px, max_err_px, max_gap: as in :func:`cdog_jax.track_groups`.
        slots: detections of one class in one view (all detections of a view without
            classes) that the first programs hold (at least 4); a frame with more raises it
            to the next rung of the shape ladder (one compile, a warning). A frame of at most
            half of them (:attr:`low_slots`, the rung that holds half) runs programs of that
            rung, also compiled on the first frame: the same answers in less time.

    Every frame's programs are compiled on the first frame and reused for every frame that
    fits; :attr:`compiles` counts the capacity raises since. State (the tracks) lives in the
    object: :meth:`reset` starts a new recording. Where JAX has several devices (CPU
    devices: :func:`cdog_jax.benchmark.use_cpu_cores`, before JAX's first operation), the
    class scenes are split into two chunks that run at once on two of them (the same
    answers; the association's program is then compiled for both on the first frame).
    """

    def __init__(
        self,
        rig: Rig,
        *,
        num_classes: int | None = None,
        class_names: Any = None,
        method: Any = None,
        sigma: float | str = "auto",
        dist: Any = None,
        min_views: int = 2,
        person_vote: Any = None,
        temporal_prior: bool = True,
        max_step: float | None = None,
        max_step_px: float = DEFAULT_MAX_STEP_PX,
        max_err_px: float | None = None,
        max_gap: int = 0,
        slots: int = DEFAULT_SLOTS,
    ):
        expect_args("LiveAssociator", rig=(rig, Rig))
        check_rig(rig)
        num_classes = given_classes(class_names, num_classes, "LiveAssociator: ")
        for name, value in (("slots", slots), ("max_gap", max_gap), ("min_views", min_views)):
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, np.integer))
                or value < (1 if name == "slots" else 0)
            ):
                raise ValueError(f"LiveAssociator: {name} must be a positive int; got {value!r}")
        if not 2 <= min_views <= rig.num_views:
            raise ValueError(
                f"LiveAssociator: min_views must be an int in [2, {rig.num_views}]; got {min_views!r}"
            )
        _check_gate("max_step", max_step, allow_none=True)
        _check_gate("max_step_px", max_step_px)
        _check_gate("max_err_px", max_err_px, allow_none=True)
        if not (
            sigma in ("auto", "held")
            or (
                isinstance(sigma, (int, float))
                and not isinstance(sigma, bool)
                and np.isfinite(sigma)
                and sigma > 0
            )
        ):
            raise ValueError(
                "LiveAssociator: sigma must be 'auto', 'held' or a finite number > 0 (px); "
                f"got {sigma!r}"
            )
        self.rig = rig
        self.classed = num_classes is not None
        self.num_classes = int(num_classes) if self.classed else 1
        self.class_names = None if class_names is None else tuple(class_names)
        self.method = method_argument(method, "LiveAssociator")
        self.sigma = sigma
        self.dist = dist
        self.lens = None if dist is None else as_lens(dist, rig.K.dtype)
        self.min_views = int(min_views)
        self.person_vote = person_vote
        self._min_votes = (
            person_vote.min_votes if isinstance(person_vote, PersonVote) else PersonVote().min_votes
        )
        self.temporal_prior = bool(temporal_prior)
        self.max_err_px, self.max_gap = max_err_px, int(max_gap)
        self.dtype = np.dtype(rig.K.dtype)
        # The tracker's gates as it reads them (scene units, or nan: pixels at the depth).
        self._gates = (
            jnp.asarray(np.nan if max_step is None else max_step, self.dtype),
            jnp.asarray(max_step_px, self.dtype),
        )
        self.slots = slot_capacity(slots)  # per class and view, the association's programs
        # A frame whose classes hold at most half of that in every view runs programs of that
        # smaller rung (compiled on the first frame too): the association's pairwise work
        # is per pair of slots, and most frames of a person detector fill half of them.
        self.low_slots = slot_capacity(max(slots // 2, 1))
        # Group rows the tracker carries: room for every class to hold half its slots' groups.
        self.rows = ladder_rung(self.num_classes * self.slots // 2, 8)
        # The class scenes in two chunks where there are several devices (each chunk of at
        # least two scenes): on several CPU devices (cdog_jax.benchmark.use_cpu_cores) they
        # run at once on two cores. Not one chunk per device: each chunk's device compiles
        # the association once on the first frame and each chunk starts a program (~0.3 ms).
        half = -(-self.num_classes // 2)
        several = len(jax.local_devices()) > 1
        self._scenes_per_chunk = half if several and half >= 2 else self.num_classes
        self.compiles = 0
        self._compiled = False
        self._vote_rows = 0  # the tracker's rows the person vote's DLT was compiled for
        self._fit_widths = [0]  # set on the first frame
        self._warmed = None  # (slots, rows) whose programs are compiled at every rung
        self.reset()

    @property
    def frame_slots(self) -> int:
        """Slots per view of the tracker's tables: every class at full capacity, so that a
        frame that fits the association's programs fits the tracker's."""
        return ladder_rung(self.num_classes * self.slots)

    def reset(self) -> None:
        """Forget every track: the next frame is frame 0 of a new recording."""
        self.frame = 0
        self._carry = None
        self._people = PersonLinker(self._min_votes)
        self.held_sigma: float | None = None  # sigma="held": the σ (px) once it is held

    def update(
        self, xy: Any, mask: Any = None, *, classes: Any = None, instances: Any = None
    ) -> LiveFrame:
        """Associate, triangulate and track one frame.

        Args:
            xy: ``(M, P, 2)`` detections (pixels), or a :class:`cdog_jax.io.Detections` of
                one frame (as the readers return it; its mask, classes and instances are
                used).
            mask: ``(M, P)`` bool (default: every slot).
            classes: ``(M, P)`` int class ids, needed when the object has classes.
            instances: ``(M, P)`` int per-view skeleton index (2D person; -1 unknown): the
                person vote, and with classes every group's person id.

        Returns:
            A :class:`LiveFrame`. Raises ``ValueError`` for a frame of the wrong shape or
            classes; the object's state is then unchanged.
        """
        xy, mask, classes, instances = self._frame(xy, mask, classes, instances)
        M, P = mask.shape
        # Each view's detections packed to the front, in order (the association sees the
        # same scenes as with the input's gaps); labels and groups go back to the input's slots.
        order = np.argsort(~mask, axis=1, kind="stable")
        count = int(mask.sum(axis=1).max())
        per_class = _most_per_class(mask, classes, self.num_classes)
        raised = per_class > self.slots
        if raised:
            what = "of one class " if self.classed else ""
            self._raise(
                "slots", slot_capacity(per_class), f"{per_class} detections {what}in one view"
            )
        if raised or not self._compiled:
            self._warm_sigma_fits(M)

        front = order[:, :count]

        def pad(a, fill):
            out = np.full((M, self.frame_slots, *a.shape[2:]), fill, a.dtype)
            out[:, :count] = np.take_along_axis(
                a, front.reshape(front.shape + (1,) * (a.ndim - 2)), axis=1
            )
            return out

        xy_p, mask_p, cls_p = pad(xy, 0), pad(mask, False), pad(classes, 0)
        inst_p = None if instances is None else pad(instances, -1)
        association = dict(
            num_classes=self.num_classes,
            method=self.method,
            sigma=self._frame_sigma(),
            dist=self.dist,
            min_views=self.min_views,
            min_scenes=self.num_classes,
            min_slots=self.low_slots if per_class <= self.low_slots else self.slots,
            batch_size=self._scenes_per_chunk,
            min_samples=self._fit_widths[0],
            checked=True,  # by _frame: the frame is not read again
        )
        frame_det = self._detections(xy_p, mask_p, cls_p)
        vote = person_vote_argument(self.person_vote, inst_p)
        frame = (xy_p[None], mask_p[None], cls_p[None])
        scenes = None
        if vote is None:  # no person vote: the scenes' results go to the tracker as they are
            scenes = associate_classes_at(self.rig, *frame, scenes_only=True, **association)
        if scenes is not None:
            out, sigma, tau, status = self._track_scenes(scenes, frame_det)
        else:  # the person vote, or a frame without a scene (its empty table on the host)
            if vote is not None and self._vote_rows != self.rows:
                # The vote's DLT at the tracker's rows, compiled now: every later frame that
                # changes a group meets it.
                warm_retriangulation(self.rig, self.rows)
                self._vote_rows = self.rows
            vote_args = dict(
                instances=None if inst_p is None else inst_p[None],
                person_vote=vote,
                min_vote_rows=self.rows,
                on_host=True,  # read here, field by field: no transfer to the device and back
            )
            result = None
            if vote is not None:  # the scenes' tables made the frame's on the device
                scenes = associate_classes_at(self.rig, *frame, scenes_only=True, **association)
                if scenes is not None:
                    result = self._voted(scenes, frame, inst_p, vote)
            if result is None:  # no scene, or more groups than the vote's table holds
                result = associate_classes_at(self.rig, *frame, **vote_args, **association)
            assoc = result.association
            sigma, tau = float(assoc.sigma_px[0]), float(assoc.tau_px[0])
            status = int(assoc.status[0])
            self._grow_rows(int(assoc.num_groups[0]))
            group_class = result.group_class if self.classed else None
            frames = tracking_frames(
                assoc,
                group_class,
                assoc.labels,
                *(a[None] for a in frame_det),
                self.max_err_px,
                self.rows,
                self.temporal_prior,
            )
            one = type(frames)(*(a[0] for a in frames))
            self._carry, out = track_one(
                self.rig,
                self._tracks(),
                one,
                *self._gates,
                prior=self.temporal_prior,
                min_views=self.min_views,
                max_gap=self.max_gap,
            )
        if self._warmed != (self.slots, self.rows):
            self._warm_other_rung(
                frame, frame_det, association, None if vote is None else vote_args
            )
        if self.sigma == "held" and self.held_sigma is None:
            if sigma > 0 and not status & Status.SIGMA_FALLBACK:  # 0: an empty frame
                self.held_sigma = sigma
        self._compiled = True
        # The frame's answer in one transfer to the host, not one per field read, without
        # the fields the answer does not hold.
        read = jax.device_get(out._replace(bpe=None, unplaced=None))
        answer = _answer(self.frame, read, order, P, self.classed, sigma, tau, status)
        if instances is not None and self.classed:
            G = len(answer.groups)
            one = people_of_frame(
                answer.groups,
                np.ones(G, bool),
                answer.group_class,
                np.where(mask, instances, -1),
                answer.points3d,
                answer.n_views,
                answer.err_px,
                self.num_classes,
                self._people,
                answer.track_id,
                self._min_votes,
            )
            answer = answer._replace(
                person_id=one.group_person,
                merged_people=tuple(int(i) for i in one.ids[one.merged]),
                split_people=tuple(int(i) for i in one.ids[one.split]),
            )
        self.frame += 1
        return answer

    def _frame(self, xy, mask, classes, instances):
        """The frame as NumPy arrays ``xy (M, P, 2)``, ``mask``, ``classes``, ``instances``,
        checked."""
        if hasattr(xy, "xy") and hasattr(xy, "mask") and hasattr(xy, "counts"):  # a Detections
            det = xy
            if det.xy.shape[0] != 1:
                raise ValueError(
                    f"LiveAssociator.update: give one frame; the detections hold {det.xy.shape[0]} frames"
                )
            xy, mask = det.xy[0], det.mask[0]
            classes = classes if det.classes is None else det.classes[0]
            instances = instances if det.instances is None else det.instances[0]
        xy = np.asarray(as_array(xy))
        if xy.ndim != 3 or xy.shape[-1] != 2:
            raise ValueError(f"LiveAssociator.update: xy must have shape (M, P, 2); got {xy.shape}")
        mask = np.ones(xy.shape[:2], bool) if mask is None else np.asarray(as_array(mask))
        check_observations(xy, mask, self.rig.num_views)
        if self.classed:
            if classes is None:
                raise ValueError(
                    "LiveAssociator.update: this associator has classes; give the frame's classes (M, P)"
                )
            classes = np.asarray(classes)
            if classes.shape != mask.shape or not np.issubdtype(classes.dtype, np.integer):
                raise ValueError(
                    f"LiveAssociator.update: classes must be integer ids of shape {mask.shape}; got {classes.shape} {classes.dtype}"
                )
            bad = mask & ((classes < 0) | (classes >= self.num_classes))
            if bad.any():
                m, i = (int(v) for v in np.argwhere(bad)[0])
                raise ValueError(
                    f"LiveAssociator.update: class {int(classes[m, i])} at view {m}, slot {i} is not in [0, {self.num_classes})"
                )
            classes = np.where(mask, classes, 0).astype(np.int64)
        else:
            classes = np.zeros(mask.shape, np.int64)
        if instances is not None:
            instances = np.asarray(instances)
            if instances.shape != mask.shape or not np.issubdtype(instances.dtype, np.integer):
                raise ValueError(
                    f"LiveAssociator.update: instances must be integer indices of shape {mask.shape}; got {instances.shape}"
                )
        return xy.astype(self.dtype), mask.astype(bool), classes, instances

    def _detections(self, xy, mask, classes) -> tuple:
        """The frame's packed detections ``(xy, mask, classes)`` as the temporal prior
        searches them (undistorted pixels), or zeros without the prior."""
        M = mask.shape[0]
        if not self.temporal_prior:
            return (
                np.zeros((M, self.frame_slots, 2), self.dtype),
                np.zeros((M, self.frame_slots), bool),
                np.zeros((M, self.frame_slots), np.int32),
            )
        if self.lens is not None:
            xy = np.asarray(undistorted_frames(self.rig, xy[None], mask[None], self.lens))[0]
        return xy.astype(self.dtype), mask, classes.astype(np.int32)

    def _grow_rows(self, found: int) -> None:
        """Raise the tracker's rows to hold a frame of ``found`` groups (its carry grown)."""
        if found <= self.rows:
            return
        old = self.rows
        self._raise("rows", ladder_rung(found), f"{found} groups")
        if self._carry is not None:
            self._carry = _on_device(
                grown_tracks(
                    self._carry, self._table_rows(old), self._table_rows(self.rows), self.max_gap
                )
            )

    def _tracks(self):
        """The tracks carried into this frame (none before the first), on the device."""
        if self._carry is None:
            self._carry = _on_device(
                initial_tracks(self._table_rows(self.rows), self.max_gap, self.dtype)
            )
        return self._carry

    def _warm_other_rung(self, frame, det, association: dict, vote_args) -> None:
        """Compile the programs of the slot rung this frame did not run (the association, and
        the tracker's step or the person vote) by running the frame cut to fit it, each
        class's first detections in a view, and discarding the answers: the tracks stay as
        they are. A frame without a scene (no class seen in two views) compiles nothing."""
        xy, mask, classes = (a[0] for a in frame)
        if not ((_per_class(mask, classes, self.num_classes) > 0).sum(axis=0) >= 2).any():
            return
        P = mask.shape[1]
        earlier = np.arange(P)[:, None] > np.arange(P)[None, :]  # [p, q]: q before p
        same = (classes[:, :, None] == classes[:, None, :]) & mask[:, None, :] & earlier
        rank = same.sum(axis=2)  # (M, P) detections of the slot's class before it in its view
        for rung in {self.low_slots, self.slots} - {association["min_slots"]}:
            kept = mask & (rank < rung)  # classes 0 where no detection, as _frame gives them
            cut = (xy[None], kept[None], np.where(kept, classes, 0)[None])
            other = dict(association, min_slots=rung)
            if vote_args is None:
                scenes = associate_classes_at(self.rig, *cut, scenes_only=True, **other)
                jax.block_until_ready(self._tracked(scenes, det))
            else:  # the association and the vote's frame table at this rung
                scenes = associate_classes_at(self.rig, *cut, scenes_only=True, **other)
                if scenes is not None:
                    self._voted(scenes, cut, vote_args["instances"][0], vote_args["person_vote"])
        self._warmed = (self.slots, self.rows)

    def _voted(self, scenes: SceneResults, frame: tuple, instances, vote):
        """The frame's groups after the person vote from its class scenes
        (:func:`vote_on_scenes`), or ``None`` where they do not fit the tracker's rows."""
        return vote_on_scenes(
            self.rig,
            scenes,
            *frame,
            instances[None],
            vote,
            rows=self.rows,
            num_classes=self.num_classes,
            dist=self.dist,
            min_views=self.min_views,
        )

    def _track_scenes(self, scenes: SceneResults, det: tuple):
        """Map the class scenes' results to the frame and track it, in one program
        (:func:`track_scenes`); a frame of more groups than the tracker's rows raises them and
        runs again. Returns the frame's table and its σ, τ and status."""
        carry, out, found = self._tracked(scenes, det)
        # The association's σ, τ and status, read while the tracker runs.
        sigma, tau, status = frame_fields(scenes.result, scenes.scenes.frame, 1, scenes.flags())
        while int(found) > self.rows:  # the tracks as they were, grown: the frame again
            self._grow_rows(int(found))
            carry, out, found = self._tracked(scenes, det)
        self._carry = carry
        return out, float(sigma[0]), float(tau[0]), int(status[0])

    def _tracked(self, scenes: SceneResults, det: tuple):
        """:func:`track_scenes` of the frame's class scenes from the tracks carried into it:
        ``(carry, table, groups found)``, the object's state unchanged."""
        sc = scenes.scenes
        max_err = np.asarray(np.nan if self.max_err_px is None else self.max_err_px, self.dtype)
        return track_scenes(
            self.rig,
            self._tracks(),
            scenes.result,
            sc.slot.astype(np.int32),
            sc.cls.astype(np.int32),
            *det,
            max_err,
            *self._gates,
            rows=self.rows,
            prior=self.temporal_prior,
            min_views=self.min_views,
            max_gap=self.max_gap,
        )

    def _frame_sigma(self) -> float | str:
        """The ``sigma`` of this frame's association: ``"auto"`` until a σ is held."""
        if self.sigma != "held":
            return self.sigma
        return "auto" if self.held_sigma is None else self.held_sigma

    def _warm_sigma_fits(self, M: int) -> None:
        """The σ fit's table widths for the current slots, each compiled now: a frame's fit
        then runs on the narrowest that holds its samples (three programs: the fullest frame's
        table, a half and a quarter of it), not on the fullest frame's."""

        def most(slots):  # used samples of a frame that fits, + 1
            return self.num_classes * slots * M * (M - 1) + 1

        self._fit_widths = sigma_fit_widths(most(self.slots))
        if self.sigma in ("auto", "held") or self.method.sigma_mode != "given":  # the fit runs
            for rung in sorted({self.low_slots, self.slots}):
                warm_sigma_fits(
                    self.rig,
                    [width for width in self._fit_widths if width <= fit_width(most(rung))],
                    self.dtype,
                    self.method.sigma_mode,
                    scenes=self.num_classes,
                    slots=rung,
                    dist=self.dist,
                )

    def _table_rows(self, rows: int) -> int:
        """Rows of the tracker's frame table: the groups', then as many free rows for
        recovered groups with the temporal prior."""
        return 2 * rows if self.temporal_prior else rows

    def _raise(self, name: str, value: int, why: str) -> None:
        if not self._compiled:  # the first frame compiles anyway: its capacities are free
            setattr(self, name, value)
            return
        warnings.warn(
            f"LiveAssociator: a frame with {why} does not fit the compiled programs ({name} = {getattr(self, name)}); "
            f"compiling once for {value}",
            stacklevel=3,
        )
        setattr(self, name, value)
        self.compiles += 1


def _on_device(tracks: tuple) -> tuple:
    """``tracks`` placed on the default device as the tracker's program returns them
    (committed there: arrays placed otherwise would make the next frame a second program)."""
    return jax.device_put(tracks, jax.local_devices()[0])


def _per_class(mask: np.ndarray, classes: np.ndarray, C: int) -> np.ndarray:
    """``(M, C)`` detections of each class in each view."""
    M = mask.shape[0]
    view = np.broadcast_to(np.arange(M)[:, None], mask.shape)[mask]
    return np.bincount(view * C + classes[mask], minlength=M * C).reshape(M, C)


def _most_per_class(mask: np.ndarray, classes: np.ndarray, C: int) -> int:
    """The most detections of one class in one view."""
    return int(_per_class(mask, classes, C).max()) if mask.any() else 0


def _answer(
    frame: int, out, order: np.ndarray, P: int, classed: bool, sigma: float, tau: float, status: int
) -> LiveFrame:
    """The tracker's table of one frame as a :class:`LiveFrame`: its valid rows, in order
    (groups of the association, then recovered ones), slots those of the input
    (``order (M, P)``: the input slot of every packed slot)."""
    valid = np.asarray(out.valid)
    rows = np.flatnonzero(valid)
    rank = np.full(valid.shape[0] + 1, -1, np.int32)
    rank[rows] = np.arange(len(rows), dtype=np.int32)
    table = np.asarray(out.labels)
    width = min(P, table.shape[1])
    labels = np.full((table.shape[0], P), -1, np.int32)
    np.put_along_axis(
        labels,
        order[:, :width],
        rank[np.where(table[:, :width] >= 0, table[:, :width], -1)],
        axis=1,
    )
    packed = np.asarray(out.groups)[rows]
    views = np.arange(packed.shape[1])[None, :]
    groups = np.where(packed >= 0, order[views, np.maximum(packed, 0)], -1).astype(np.int32)
    return LiveFrame(
        frame=frame,
        labels=labels,
        groups=groups,
        points3d=np.asarray(out.X)[rows],
        err_px=np.asarray(out.err_px)[rows],
        n_views=np.sum(groups >= 0, axis=1, dtype=np.int32),
        track_id=np.asarray(out.track)[rows],
        recovered=np.asarray(out.recovered)[rows],
        group_class=np.asarray(out.cls)[rows] if classed else None,
        sigma_px=sigma,
        tau_px=tau,
        status=status,
    )

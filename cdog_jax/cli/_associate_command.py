"""``cdog-jax associate`` and ``cdog-jax rig``: the user's own cameras and detections.

``associate`` reads a rig file (any format of :func:`cdog_jax.io.load_rig`) and detections
(:func:`cdog_jax.io.load_detections`: one scene or many frames; an OpenPose folder of
camera folders, :func:`cdog_jax.io.load_openpose`; a table ``frame, view, class, x, y,
score``, :func:`cdog_jax.io.load_keypoint_table`), checks both before any work, associates
every frame in one compiled call (undistorting first when the rig carries distortion),
prints a short summary, and writes the groups (JSON, NPZ or CSV by the extension of
``--out``) and optionally a figure of the first frame. Detections with classes (keypoint
types, or the JSON's ``"classes"``/``"by_class"``) are associated class by class
(:func:`cdog_jax.associate_classes`: different classes are never joined), and every
output carries each group's class. ``rig`` prints
:meth:`cdog_jax.Rig.describe` and optionally draws the rig.

Before any work: the inputs exist and are of the right kind, the outputs can be written
and are none of the inputs (``_paths.py``), the files are read and checked, and
σ is finite and at most the image diagonal (the rig file's image size, else twice the
principal point). Frames that cannot give a group (fewer than 2 views with detections)
get zero groups and a note.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import tempfile
import time
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import (
    Status,
    associate_batch,
    method_from,
)
from .._result import Association
from .._runtime.memory import release_freed_memory
from .._status import status_messages
from ..geometry import describe_rig
from ..geometry._distortion import Fisheye
from ..graph._sigma import FALLBACK_SIGMA_PX
from ..io import (
    load_detections,
    load_keypoint_table,
    load_openpose,
    load_rig,
    save_association_csv,
    save_association_json,
    save_association_npz,
)
from ..io._association_files import CsvParts, JsonParts, NpzParts
from ..io._atomic import atomic_savefig
from ..io._detections_checks import check_float_range
from ..io._errors import InputError
from ..io._keypoints import SKELETONS, OpenPoseParts, _OpenPoseFiles
from ..io._read_files import open_npz
from ..io._rig_files import FORMATS
from ..io._trc import TrcParts, person_markers, save_people_trc, save_trc, track_markers
from ..people._classes import associate_classes_at
from ..people._persons import PersonLinker, people_part
from ..tracking._tracks import track_part
from ._common import (
    _FIGURE_EXTENSIONS,
    _emit,
    _positive_int,
    add_method_argument,
    check_sigma_fits,
    int_at_least,
)
from ._paths import check_distinct, check_input, check_output, input_files, write_output as _write

_POINT_FORMATS = ("auto", "detections", "openpose", "table")
_OUT_FORMATS = (".json", ".npz", ".csv", ".trc")
_NOTES_SHOWN = 12  # notes printed in the summary; a long video can have thousands


def _sigma(text: str) -> float | str:
    if text in ("auto", "robust"):
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'must be a number of pixels >= 0, "auto" or "robust"; got {text!r}'
        ) from None
    if not (value >= 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(
            f'must be a finite number of pixels >= 0, "auto" or "robust"; got {text!r}'
        )
    return value


_min_views = int_at_least(2, " (a group needs two views)")


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0; got {text!r}") from None
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0; got {text!r}")
    return value


def _units(text: str) -> str:
    if not text or any(c.isspace() for c in text):
        raise argparse.ArgumentTypeError(
            f"must be a unit's name without spaces, such as m or mm; got {text!r}"
        )
    return text


_RIG_FORMATS_TEXT = (
    "an EasyVis/OpenMVG folder (K0.txt, R0.txt, T0.txt, ...), the project's .json or .npz, an anipose "
    "calibration.toml, a COLMAP text model (cameras.txt + images.txt), EasyMocap intri.yml + extri.yml, "
    "a nerfstudio transforms.json or a Qualisys .qca.txt"
)
_ASSOCIATE_DESCRIPTION = (
    "Associate the detections of your cameras: read a rig (" + _RIG_FORMATS_TEXT + ") and a "
    "detections file (JSON or NPZ, one scene or many frames; docs/CONVENTIONS.md §3), check "
    "both before any work, associate every frame (undistorting first when the rig has "
    "distortion), print a summary and write the groups and their 3D points (JSON, NPZ or CSV "
    "by the extension of --out) and optionally a figure of the first frame. Frames with fewer "
    "than 2 views with detections get zero groups and a note. Try it on the example files: "
    "cdog-jax associate --rig examples/rig.json --points examples/detections.json"
)
_RIG_DESCRIPTION = (
    "Describe a rig file (" + _RIG_FORMATS_TEXT + "): camera centres, viewing directions, "
    "focal lengths, baselines and warnings (a camera looking away from the detections, "
    "axes meeting behind the cameras, a rig that reads right only as camera-to-world), and "
    "optionally draw it."
)


def add_parsers(subparsers) -> None:
    """Declare ``associate`` and ``rig``."""
    p = subparsers.add_parser(
        "associate",
        help="associate your detections with your rig; write groups and 3D points",
        description=_ASSOCIATE_DESCRIPTION,
    )
    p.add_argument("--rig", required=True, help="rig file or folder")
    p.add_argument(
        "--rig-format",
        default="auto",
        choices=("auto", *FORMATS),
        help="rig format (default: from the path)",
    )
    p.add_argument(
        "--points",
        required=True,
        help="detections: a .json or .npz file (one scene or many frames), a folder of OpenPose camera folders, "
        "or a table .csv/.npz (frame, view, class, x, y[, score])",
    )
    p.add_argument(
        "--points-format",
        choices=_POINT_FORMATS,
        default="auto",
        help="detections format (default: a folder is openpose, .csv a table, .npz with a 'frame' array a table)",
    )
    p.add_argument(
        "--keypoints",
        default=None,
        help="names of the OpenPose keypoint types: "
        + ", ".join(SKELETONS)
        + " (default: ids only)",
    )
    p.add_argument(
        "--sigma",
        type=_sigma,
        default="auto",
        help='detection noise σ in px; "auto" (default) estimates it assuming Gaussian noise (on '
        'real pose keypoints too it finds more joints); "robust" estimates it allowing heavy '
        "tails, nearer the true σ when far-off detections are common",
    )
    add_method_argument(p)
    p.add_argument(
        "--min-views",
        type=_min_views,
        default=2,
        help="report only groups seen in at least K views (default 2)",
    )
    p.add_argument(
        "--confidence-weights",
        action="store_true",
        help="triangulate with the detections' confidences as DLT weights (needs [x, y, c] entries)",
    )
    p.add_argument(
        "--person-vote",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="keypoints with a per-view person index (OpenPose, or a table's instance column): make each frame's "
        "joint groups consistent with the people (a person-level vote, then re-association of the joints that "
        "disagree; default: on when the detections carry that index)",
    )
    p.add_argument(
        "--capacity",
        type=_positive_int,
        default=None,
        help="slots per view (default: the largest view); refuse if exceeded",
    )
    p.add_argument(
        "--out",
        default=None,
        help="write the groups: .json (members, point, BPE), .npz (arrays), .csv (one row per 3D point) or .trc (marker "
        "trajectories for OpenSim/Pose2Sim: one file per person, <stem>_person<id>.trc, with per-view people; else one "
        "marker per track); with per-view people every group carries its person id",
    )
    p.add_argument(
        "--fps",
        type=_positive_float,
        default=30.0,
        help="frame rate written in a .trc file (default 30)",
    )
    p.add_argument(
        "--units",
        type=_units,
        default="m",
        help="the rig's length unit, written in a .trc file (default m)",
    )
    p.add_argument(
        "--z-up",
        action="store_true",
        help="the world's up axis is Z: write a .trc file with Y up, as OpenSim expects",
    )
    p.add_argument(
        "--plot", default=None, help="figure of the first frame's groups (.png, .pdf, .svg, .jpg)"
    )
    p.add_argument(
        "--batch-size",
        type=_positive_int,
        default=16,
        help="frames associated at once (memory bound)",
    )
    p.add_argument(
        "--part-frames",
        type=_positive_int,
        default=PART_FRAMES,
        help="a recording more than a quarter longer than this many frames is associated, "
        "tracked and identified in parts of it, one after the other (memory: that of one "
        f"part; default {PART_FRAMES})",
    )
    p.add_argument(
        "--temporal-prior",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="many frames: recover a point missed in a frame from the unassigned detections near its last "
        "point's reprojections (default: on for a sequence)",
    )
    p.add_argument(
        "--track-step-px",
        type=_positive_float,
        default=60.0,
        help="many frames: the most a point moves between frames, in pixels at its depth (track linking and the prior; default 60)",
    )
    p.set_defaults(func=run_associate)

    r = subparsers.add_parser(
        "rig",
        help="describe a rig file: centres, directions, baselines, warnings",
        description=_RIG_DESCRIPTION,
    )
    r.add_argument("rig", help="rig file or folder")
    r.add_argument(
        "--rig-format",
        default="auto",
        choices=("auto", *FORMATS),
        help="rig format (default: from the path)",
    )
    r.add_argument(
        "--points",
        default=None,
        help="detections file: check the cameras look at their triangulated centroid",
    )
    r.add_argument(
        "--plot", default=None, help="figure of the camera frusta (.png, .pdf, .svg, .jpg)"
    )
    r.set_defaults(func=run_rig)


PART_FRAMES = 300
"""Frames of a recording associated at once by ``cdog-jax associate``: a longer one goes in
parts (the tracks and people continue from part to part), so its memory stays that of one."""


def in_parts(frames: int, part_frames: int) -> bool:
    """A recording of ``frames`` goes in parts of ``part_frames``: when it is more than a
    quarter longer than one part. Up to that it is one part: split, its short last part
    would be padded to a whole part's work (a recording of 301 frames in parts of 300 would
    cost two parts' time) for a peak memory a quarter lower at most."""
    return frames > part_frames + part_frames // 4


_DONE = object()
"""What a streamed part's results are replaced with once written (they are not kept)."""

_PROGRESS_STEPS = 20  # frames are associated in about this many calls, for the progress bar


def _associate_frames(call, xy, mask, weights, batch_size: int):
    """``call(xy, mask, weights)`` over chunks of the ``F`` frames, with a progress bar,
    and the results joined: one chunk (one call) up to ``_PROGRESS_STEPS`` batches, else
    chunks of a whole number of batches, the last padded with copies of the last frame
    (one shape, one compiled program), the copies' results dropped."""
    # The progress bar (tqdm) loads when a run shows one.
    from .._runtime.progress import bar, compiling

    F = xy.shape[0]
    chunk = batch_size * max(1, math.ceil(F / (batch_size * _PROGRESS_STEPS)))
    if F <= chunk:
        with compiling(f"the association of {F} frame(s) (with its run)"):
            return jax.block_until_ready(call(xy, mask, weights))
    pad = -F % chunk

    def padded(a):
        return None if a is None else jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)])

    xy, mask, weights = padded(xy), padded(mask), padded(weights)
    frames = bar(F, "associate", unit="frame")
    parts = []
    for start in range(0, F + pad, chunk):
        part = slice(start, start + chunk)
        with (
            compiling(f"the association of {chunk} frames (with its first run)")
            if start == 0
            else contextlib.nullcontext()
        ):
            parts.append(
                jax.block_until_ready(
                    call(xy[part], mask[part], None if weights is None else weights[part])
                )
            )
        frames.update(min(chunk, F - start))
    frames.close()
    return jax.tree.map(lambda *a: jnp.concatenate(a)[:F], *parts)


def _check_paths(args, outputs: dict[str, tuple[str | None, tuple[str, ...]]]) -> None:
    """Inputs exist with the right kind; every output (flag → (path, extensions)) can be
    written, differs from the others and from every input file. Before any reading."""
    folder_formats = ("easyvis", "colmap", "easymocap")
    kind = (
        "folder"
        if args.rig_format == "easyvis"
        else "file"
        if args.rig_format in ("json", "npz", "anipose")
        else "any"
    )
    check_input(args.rig, "--rig", kind=kind)
    inputs = {
        "--rig": input_files(args.rig)
        if args.rig_format in ("auto", *folder_formats)
        else [args.rig]
    }
    if getattr(args, "points", None):
        fmt = getattr(args, "points_format", "auto")
        named_file = os.path.splitext(args.points)[1].lower() in (
            ".json",
            ".npz",
            ".csv",
        )  # a folder "x.json" is a mistake
        folder_ok = fmt == "openpose" or (fmt == "auto" and not named_file)
        check_input(args.points, "--points", kind="any" if folder_ok else "file")
        inputs["--points"] = _point_files(args.points)
    check_distinct({flag: path for flag, (path, _) in outputs.items()})
    for flag, (path, extensions) in outputs.items():
        if path is not None:
            check_output(path, flag, extensions, inputs)


def _point_files(path: str) -> list[str]:
    """Every file that reading ``--points`` may read (an OpenPose folder: all its files)."""
    if not os.path.isdir(path):
        return [path]
    return [os.path.join(root, name) for root, _, names in os.walk(path) for name in names]


def _points_format(path: str, given: str) -> str:
    if given != "auto":
        return given
    if os.path.isdir(path):
        return "openpose"
    suffix = os.path.splitext(path)[1].lower()
    if suffix == ".csv":
        return "table"
    if suffix == ".npz":
        with open_npz(path) as npz:
            return "table" if "frame" in npz.files else "detections"
    return "detections"


def _load(args):
    """Rig file and detections, checked against each other (views, image size, capacity)."""
    # Far from its world's origin (UTM-like coordinates) the rig is centred on its cameras,
    # so that float32 holds it; the outputs' points are put back in the file's world.
    rig_file = load_rig(args.rig, format=args.rig_format, origin="auto")
    detections = None
    if getattr(args, "points", None):
        checks = dict(
            num_views=rig_file.rig.num_views,
            capacity=getattr(args, "capacity", None),
            image_size=rig_file.image_size,
        )
        fmt = _points_format(args.points, getattr(args, "points_format", "auto"))
        keypoints = getattr(args, "keypoints", None)
        if keypoints is not None and fmt != "openpose":
            raise InputError(
                f"{args.points}: --keypoints names OpenPose keypoints; the detections are not an OpenPose folder"
            )
        if fmt == "openpose":
            if keypoints is not None and keypoints not in SKELETONS:
                raise InputError(
                    f"--keypoints: expected one of {', '.join(SKELETONS)}; got {keypoints!r}"
                )
            part_frames = getattr(args, "part_frames", None)
            if part_frames and in_parts(
                len(_OpenPoseFiles(args.points, None).frame_ids), part_frames
            ):
                tally = _Tally(rig_file.rig.K.dtype, args.points)
                reader = OpenPoseParts(
                    args.points,
                    keypoints=keypoints,
                    part_frames=part_frames,
                    inspect=tally,
                    **checks,
                )
                parts = _Parts(reader, tally.detections, tally.shapes)
                return rig_file, reader.read(0)._replace(notes=reader.notes), parts
            detections = load_openpose(args.points, keypoints=keypoints, **checks)
        elif fmt == "table":
            detections = load_keypoint_table(args.points, **checks)
        else:
            detections = load_detections(args.points, **checks)
    return rig_file, detections, None


class _Parts(NamedTuple):
    """An OpenPose recording longer than ``--part-frames``, read a part at a time: the
    reader, the detections of all its frames, the classes' program shapes for all of them
    (:func:`_class_shapes`)."""

    reader: Any
    detections: int
    shapes: dict


class _Tally:
    """What ``associate`` needs of every part of a recording before any work: each part's
    coordinates checked against the float type, the detections counted, the largest class
    shapes kept."""

    def __init__(self, dtype, source: str):
        self.dtype, self.source = dtype, source
        self.detections, self.shapes = 0, {"min_slots": 0, "min_samples": 0}

    def __call__(self, frames: slice, det) -> None:
        check_float_range(det, self.dtype, self.source, frames.start)
        self.detections += int(det.mask.sum())
        for key, value in _class_shapes(det).items():
            self.shapes[key] = max(self.shapes[key], value)


# The per-frame arrays of detections, and what pads them (an empty frame).
_FRAME_ARRAYS = (
    ("xy", 0),
    ("mask", False),
    ("confidence", 0),
    ("counts", 0),
    ("classes", -1),
    ("frame_ids", -1),
    ("instances", -1),
)


def _each_frame_array(det, change):
    """``det`` with ``change(array, fill)`` of each of its per-frame arrays."""
    arrays = {name: getattr(det, name) for name, _ in _FRAME_ARRAYS}
    return det._replace(
        **{
            name: None if arrays[name] is None else change(arrays[name], fill)
            for name, fill in _FRAME_ARRAYS
        }
    )


def _padded(det, F: int):
    """``det`` with empty frames after its own, ``F`` in all."""
    extra = F - det.mask.shape[0]
    return _each_frame_array(
        det,
        lambda a, fill: np.concatenate([a, np.full((extra, *a.shape[1:]), fill, a.dtype)]),
    )


def _first_frames(result, n: int):
    """A result of frames (an association, a classed or tracked one, people) cut to its
    first ``n`` frames."""
    # On the host: slicing a device array would be an eager operation, compiled per shape.
    if result is None or not hasattr(result, "_fields"):  # an Association: every leaf
        cut = lambda a: np.asarray(a)[:n]  # noqa: E731
        return None if result is None else jax.tree_util.tree_map(cut, result)
    fields = {}
    for name, value in result._asdict().items():
        if hasattr(value, "labels") and hasattr(value, "valid"):
            fields[name] = _first_frames(value, n)
        elif isinstance(value, (np.ndarray, jax.Array)) and value.ndim:
            fields[name] = np.asarray(value)[:n]
    return result._replace(**fields)


def _in_world(result, origin: np.ndarray):
    """A result (an association, a classed or tracked one, people) with its 3D points moved
    from the centred rig's frame back to the rig file's world: float64 points, ``origin``
    added to every valid group's point (padding rows keep 0) and to every person's."""
    if result is None:
        return result
    if isinstance(result, Association):
        points = np.asarray(result.points3d, np.float64)
        valid = np.asarray(result.valid)[..., None]
        return eqx.tree_at(lambda a: a.points3d, result, np.where(valid, points + origin, points))
    if hasattr(result, "association"):  # classed or tracked
        return result._replace(association=_in_world(result.association, origin))
    return result._replace(points=np.asarray(result.points, np.float64) + origin)  # People


def _part_of(det, frames: slice):
    """The detections of ``frames`` of a whole recording's ``det``."""
    return _each_frame_array(det, lambda a, _: a[frames])


def refuse_camera_to_world(rig_file, path: str, det=None) -> None:
    """Refuse a rig that points wrong as given and right read as camera→world (the other
    convention), judged on the frame with the most detections when ``det`` is given, else
    on where the optical axes meet; before any work. The detections' rays are cast without
    the lens: the test is coarse (cameras facing away), and stays on the host."""
    xy = mask = None
    if det is not None and det.mask.any():
        f = int(np.argmax(det.mask.sum(axis=(1, 2))))
        xy, mask = det.xy[f], det.mask[f]
    if describe_rig(rig_file.rig, xy=xy, mask=mask, image_size=rig_file.image_size).camera_to_world:
        raise InputError(
            f"{path}: the cameras point away from the scene as given, and at it when R, t are "
            "read as camera→world: the rig was probably written camera→world; this library "
            "expects world→camera (X_cam = R X + t, i.e. R' = Rᵀ, t' = −Rᵀ t of what the file "
            "holds); 'cdog-jax rig' shows the details"
        )


def _image_diagonal(rig_file) -> tuple[float, str]:
    """The image diagonal (px) and where it comes from: the rig file's image sizes (the
    largest view), else twice the principal point of ``K / K[2,2]`` (the largest view)."""
    if rig_file.view_sizes is not None:
        w, h = np.asarray(rig_file.view_sizes, np.float64).T
        return float(np.max(np.hypot(w, h))), "image size of the rig file"
    K = np.asarray(rig_file.rig.K, np.float64)
    K = K / K[:, 2:3, 2:3]
    return float(
        np.max(np.hypot(2 * K[:, 0, 2], 2 * K[:, 1, 2]))
    ), "twice the principal point; the rig file has no image size"


def run_associate(args: argparse.Namespace) -> int:
    """Load, check, associate all frames, print a summary, write the outputs."""
    _check_paths(
        args, {"--out": (args.out, _OUT_FORMATS), "--plot": (args.plot, _FIGURE_EXTENSIONS)}
    )
    rig_file, det, parts = _load(args)  # parts: a long OpenPose recording, det its first part
    refuse_camera_to_world(rig_file, args.rig, det)
    if args.confidence_weights and det.confidence is None:
        raise InputError(
            f"{args.points}: --confidence-weights: the file has no confidences (entries [x, y, c])"
        )
    people_known = det.classes is not None and det.instances is not None
    if args.person_vote and not people_known:
        raise InputError(
            f"{args.points}: --person-vote: the detections carry no per-view person index "
            "(an OpenPose folder, or a table with an instance column)"
        )
    # On by default where the data allow them: both win on real recordings (docs/GUIDE.md).
    vote = people_known if args.person_vote is None else args.person_vote
    prior = args.temporal_prior is not False
    rig = rig_file.rig
    dtype = rig.K.dtype
    trc = args.out is not None and os.path.splitext(args.out)[1].lower() == ".trc"
    if (
        trc
        and not det.frames
        and det.mask.shape[0] == 1
        and (det.classes is None or det.instances is None)
    ):
        raise InputError(
            f"{args.out}: --out .trc: marker trajectories need a sequence of frames or per-view people "
            "(an OpenPose folder); one scene has neither"
        )
    if parts is None:  # a long recording's parts: checked as they were read
        check_float_range(det, dtype, args.points)
    if not isinstance(args.sigma, str):
        diagonal, source = _image_diagonal(rig_file)
        check_sigma_fits(args.sigma, diagonal, f"{args.rig} ({source})")
    method = method_from(args.method, "cdog-jax associate")
    estimator = args.sigma
    if args.sigma == "robust":
        try:
            method = method.replace(sigma_mode="robust")
        except (TypeError, ValueError) as error:
            raise InputError(
                f"--sigma robust: the method {args.method!r} has no robust σ estimator ({error})"
            ) from None
        args.sigma = "auto"
    F, M, P = det.mask.shape
    if parts is not None:
        F = len(parts.reader.frame_ids)
    lines = [
        f"Rig: {args.rig} ({M} views"
        + (f", {rig_file.image_size[0]}×{rig_file.image_size[1]} px" if rig_file.image_size else "")
        + (", with lens distortion" if _has_lens(rig_file.dist) else "")
        + ")",
        f"Detections: {args.points}: {F} frame(s), "
        f"{int(det.mask.sum()) if parts is None else parts.detections} detections, at most {P} per view",
    ]
    if rig_file.origin is not None:
        x, y, z = rig_file.origin
        lines.append(
            f"  note: the cameras lie far from the rig's world origin; associated about their mean "
            f"centre ({x:.3f}, {y:.3f}, {z:.3f}), the output's points in the rig's world"
        )
    lines += [f"  note: {n}" for n in det.notes[:_NOTES_SHOWN]]
    if len(det.notes) > _NOTES_SHOWN:
        lines.append(f"  … and {len(det.notes) - _NOTES_SHOWN} more notes")
    dist = None
    if _has_lens(rig_file.dist):
        dist = (
            Fisheye(jnp.asarray(rig_file.dist.coeffs, dtype))
            if isinstance(rig_file.dist, Fisheye)
            else jnp.asarray(rig_file.dist, dtype)
        )
    weighted = args.confidence_weights

    t0 = time.perf_counter()
    sequence = bool(det.frames) or F > 1

    def associate_part(part):
        """The association of the detections ``part`` (with classes: by class), then their
        tracks (continuing the tracker) and people (continuing the linker)."""
        nonlocal tracker
        xy = np.asarray(part.xy, dtype)
        weights = np.asarray(part.confidence, dtype) if weighted else None
        classed = tracked = people = None
        if part.classes is not None:
            classed = associate_classes_at(
                rig,
                xy,
                part.mask,
                part.classes,
                class_names=part.class_names,
                num_classes=num_classes,
                method=method,
                sigma=args.sigma,
                dist=dist,
                weights=weights,
                min_views=args.min_views,
                batch_size=max(args.batch_size, 64),
                instances=part.instances if vote else None,
                person_vote=vote,
                **shapes,
            )
            result = classed.association
        else:
            result = _associate_frames(
                lambda xy, mask, w: associate_batch(
                    rig,
                    xy,
                    mask,
                    method=method,
                    sigma=args.sigma,
                    dist=dist,
                    weights=w,
                    min_views=args.min_views,
                    batch_size=args.batch_size,
                ),
                jnp.asarray(xy),
                jnp.asarray(part.mask),
                None if weights is None else jnp.asarray(weights),
                args.batch_size,
            )
        if sequence:  # every group gets a track id
            tracked, tracker = track_part(
                rig,
                classed if classed is not None else result,
                tracker,
                xy=xy,
                mask=part.mask,
                classes=part.classes,
                temporal_prior=prior,
                max_step=None,
                max_step_px=args.track_step_px,
                max_err_px=None,
                max_gap=0,
                min_views=args.min_views,
                dist=dist,
            )
        if classed is not None and part.instances is not None:
            people = people_part(
                tracked if tracked is not None else classed, part.instances, linker
            )
        return classed, tracked, people, result

    # A long recording goes in parts of --part-frames frames, each continuing the tracks and
    # the people of the one before: its memory is that of one part (an OpenPose folder's
    # part is read when its turn comes).
    tracker, linker = None, PersonLinker(2.0)
    frames = [slice(s, s + args.part_frames) for s in range(0, F, args.part_frames)]
    if parts is not None:
        frames = parts.reader.parts
    elif not sequence or not in_parts(F, args.part_frames):
        frames = [slice(None)]
    # Every part meets the programs the first compiled: the whole recording's shapes.
    num_classes, shapes = None, {}
    if len(frames) > 1 and det.classes is not None:
        shapes = _class_shapes(det) if parts is None else parts.shapes
        num_classes = (
            len(det.class_names)
            if det.class_names is not None
            else (parts.reader.J if parts is not None else int(det.classes[det.mask].max()) + 1)
        )
    ext = None if args.out is None else os.path.splitext(args.out)[1].lower()
    # In parts, an output file (or none) keeps nothing of a part but its summary: what is
    # written of it waits on disk beside the output.
    parts_writer = {".npz": NpzParts, ".json": JsonParts, ".csv": CsvParts, ".trc": TrcParts}
    streamed = len(frames) > 1
    out_parts = None
    if streamed and ext is not None:  # removed when written, or when the process ends
        waiting = tempfile.TemporaryDirectory(
            prefix=".cdog-jax-parts-", dir=os.path.dirname(os.path.abspath(args.out))
        )
        out_parts = parts_writer[ext](waiting.name)
    counts, most, stats = [], [], []
    for k, part_frames in enumerate(frames):
        if len(frames) == 1:
            part = det
        else:
            part = (
                _part_of(det, part_frames)
                if parts is None
                else (det if k == 0 else parts.reader.read(k))  # det: the first part, read
            )
        n = part.mask.shape[0]
        if len(frames) > 1 and n < args.part_frames:
            # The last part, padded with empty frames to meet the other parts' programs
            part = _padded(part, args.part_frames)
            outputs = associate_part(part)
            part = _part_of(part, slice(0, n))
            classed, tracked, people, result = (_first_frames(x, n) for x in outputs)
        else:
            classed, tracked, people, result = associate_part(part)
        if classed is not None:
            counts.append(_class_counts(classed))
            most.append(_class_most(part, classed.num_classes))
        stats.append(_stats(result if tracked is None else tracked.association, tracked, people))
        if k == 0 and args.plot is not None:
            first_result = jax.tree_util.tree_map(lambda a: np.asarray(a)[:1], result)
        if rig_file.origin is not None:  # what is written: points in the rig file's world
            classed, tracked, people, result = (
                _in_world(x, rig_file.origin) for x in (classed, tracked, people, result)
            )
        # Of a part, only what is written is kept (the next part's memory is the same).
        if out_parts is not None:
            _write(
                args.out,
                "--out",
                lambda: out_parts.add(
                    tracked,
                    part.xy,
                    part.mask,
                    confidence=part.confidence,
                    classes=part.classes,
                    people=people,
                ),
            )
        if streamed:  # nothing of this part stays alive while the next is associated
            classed = tracked = result = people = part = _DONE
            if parts is not None and k == 0:  # of the first part read, frame 0 (the figure's)
                det = _each_frame_array(det, lambda a, _: a[:1].copy())
            release_freed_memory()  # and the heap it used goes back to the system
    class_counts = None if not counts else (np.concatenate(counts), np.concatenate(most))
    summary = _joined(stats)
    if tracked is not None and tracked is not _DONE:
        result = tracked.association
    elapsed = time.perf_counter() - t0
    num_groups = summary.num_groups
    total = int(det.mask.sum()) if parts is None else parts.detections
    lines += [
        f"Associated with {args.method} (σ {'estimated' + (' (robust)' if estimator == 'robust' else '') if args.sigma == 'auto' else f'= {args.sigma:g} px'}, "
        f"min views {args.min_views}) in {elapsed:.2f} s including compilation",
        f"  3D points: {int(num_groups.sum())} ({num_groups.min()}–{num_groups.max()} per frame)"
        if F > 1
        else f"  3D points: {int(num_groups.sum())}",
        f"  detections assigned: {summary.assigned} of {total}",
    ]
    if class_counts is not None:
        lines.append(_class_summary(*class_counts))
    if summary.people is not None:
        lines.append(_people_summary(*summary.people))
    if summary.tracks is None and args.temporal_prior:  # asked for explicitly
        lines.append(
            "  note: --temporal-prior needs a sequence of frames; one scene has nothing to carry over"
        )
    if summary.tracks is not None:
        lines.append(
            f"  tracks: {summary.tracks} over {F} frame(s)"
            + (f"; {summary.recovered} point(s) recovered by the temporal prior" if prior else "")
        )
        if summary.unplaced:
            lines.append(
                f"  warning: the temporal prior found {summary.unplaced} point(s) it had no room to store"
            )
    n_views, err = summary.n_views, summary.err
    if n_views.size:
        counts = np.bincount(n_views, minlength=M + 1)
        lines.append(
            "  views per point: "
            + ", ".join(f"{k}: {counts[k]}" for k in range(2, M + 1) if counts[k])
        )
        lines.append(
            f"  reprojection error err_px (mean distance over a group's views): mean {err.mean():.2f} px, "
            f"median {np.median(err):.2f}, max {err.max():.2f}"
        )
    fallback = np.flatnonzero(summary.status & int(Status.SIGMA_FALLBACK))
    lines.append(
        "  σ used: "
        + ", ".join(f"{s:.2f}" for s in summary.sigma[:8])
        + (" …" if F > 8 else "")
        + " px"
        + (
            f" (not estimated in {len(fallback)} of {F} frame(s), e.g. frame {fallback[0]}: "
            f"too little evidence to estimate σ, the fallback {FALLBACK_SIGMA_PX:g} px, or an "
            "implausibly large estimate, 1 % of the focal length; pass --sigma)"
            if fallback.size
            else ""
        )
    )

    status = summary.status
    for flag in Status:  # the σ fallback is said on the line above
        hit = (
            int(np.count_nonzero(status & int(flag)))
            if flag not in (Status.OK, Status.SIGMA_FALLBACK)
            else 0
        )
        if hit:
            lines.append(f"  warning: {hit} of {F} frame(s): {status_messages(int(flag))[0]}")
    if out_parts is not None:
        if ext == ".trc":
            lines.append(_write_trc(args, None, None, parts=out_parts))
        else:
            _write(args.out, "--out", lambda: out_parts.write(args.out))
            lines.append(f"Wrote {args.out}")
        waiting.cleanup()
    elif args.out is not None:
        one = F == 1 and not det.frames
        frame = (lambda a: a[0]) if one else (lambda a: a)
        assoc = jax.tree_util.tree_map(frame, result)
        xy, mask = frame(det.xy), frame(det.mask)
        conf = None if det.confidence is None else frame(det.confidence)
        cls = None if det.classes is None else frame(det.classes)
        if tracked is not None:
            assoc = tracked
        elif classed is not None:
            assoc = classed._replace(association=assoc, group_class=frame(classed.group_class))
        if ext == ".json":
            _write(
                args.out,
                "--out",
                lambda: save_association_json(
                    args.out, assoc, xy, mask, confidence=conf, classes=cls, people=people
                ),
            )
        elif ext == ".npz":
            _write(
                args.out,
                "--out",
                lambda: save_association_npz(
                    args.out, assoc, xy=xy, mask=mask, confidence=conf, classes=cls, people=people
                ),
            )
        elif ext == ".csv":
            _write(args.out, "--out", lambda: save_association_csv(args.out, assoc, people=people))
        else:
            lines.append(_write_trc(args, people, tracked))
        if ext != ".trc":
            lines.append(f"Wrote {args.out}")
    if args.plot is not None:
        # The figures (matplotlib) and the scenes' image size load only when a plot is asked for.
        from ..synthetic._box import intrinsics_image_size
        from ..viz import plot_association

        first = jax.tree_util.tree_map(lambda a: a[0], first_result)
        size = rig_file.image_size or intrinsics_image_size(rig.K)
        _write(
            args.plot,
            "--plot",
            lambda: plot_association(
                rig,
                det.xy[0],
                det.mask[0],
                first,
                image_size=size,
                title=f"{args.points}, frame 0",
                path=args.plot,
            ),
        )
        lines.append(f"Figure: {args.plot}")
    _emit(lines)
    return 0


def _people_summary(num_people: int, present, merged, split, mixed: int) -> str:
    """People: ids, most per frame (``present (F,)``), and the frames where people merge or
    split (``merged``, ``split (F,)`` bool)."""
    F = present.shape[0]
    text = f"  people: {num_people} id(s) over {F} frame(s), at most {int(present.max())} per frame"
    flags = [(merged, "two people merged into one"), (split, "a person split in two")]
    for hit, what in flags:
        if hit.any():
            text += f"; warning: {what} in {int(hit.sum())} frame(s) (first: frame {int(np.argmax(hit))})"
    if mixed:
        text += f"; warning: {mixed} group(s) hold detections of two people"
    return text


class _Stats(NamedTuple):
    """What the summary says of a part's results (or of every part's, :func:`_joined`)."""

    num_groups: np.ndarray  # (F,)
    n_views: np.ndarray  # every valid group's
    err: np.ndarray  # every valid group's err_px
    assigned: int  # detections in a group
    sigma: np.ndarray  # (F,) σ used
    status: np.ndarray  # (F,)
    tracks: int | None
    recovered: int
    unplaced: int
    people: tuple | None  # (ids given, people per frame, merged, split (F,), mixed groups)


def _stats(result, tracked, people) -> _Stats:
    valid = np.asarray(result.valid)
    people_stats = None
    if people is not None:
        people_stats = (
            people.num_people,
            (np.asarray(people.person_id) >= 0).sum(axis=1),
            np.asarray(people.merged).any(axis=1),
            np.asarray(people.split).any(axis=1),
            int(np.asarray(people.mixed).sum()),
        )
    return _Stats(
        num_groups=np.asarray(result.num_groups).reshape(-1),
        n_views=np.asarray(result.n_views)[valid],
        err=np.asarray(result.err_px)[valid],
        assigned=int((np.asarray(result.labels) >= 0).sum()),
        sigma=np.asarray(result.sigma_px).reshape(-1),
        status=np.asarray(result.status).reshape(-1),
        tracks=None if tracked is None else tracked.num_tracks,
        recovered=0 if tracked is None else int(np.asarray(tracked.recovered).sum()),
        unplaced=0 if tracked is None else int(np.asarray(tracked.unplaced).sum()),
        people=people_stats,
    )


def _joined(stats: list[_Stats]) -> _Stats:
    """The summary of parts of one recording, one after the other."""
    if len(stats) == 1:
        return stats[0]
    cat = lambda values: np.concatenate(list(values))  # noqa: E731
    people = None
    if stats[0].people is not None:
        people = (
            stats[-1].people[0],
            *(cat(s.people[k] for s in stats) for k in (1, 2, 3)),
            sum(s.people[4] for s in stats),
        )
    return _Stats(
        num_groups=cat(s.num_groups for s in stats),
        n_views=cat(s.n_views for s in stats),
        err=cat(s.err for s in stats),
        assigned=sum(s.assigned for s in stats),
        sigma=cat(s.sigma for s in stats),
        status=cat(s.status for s in stats),
        tracks=None if stats[0].tracks is None else max(s.tracks for s in stats),
        recovered=sum(s.recovered for s in stats),
        unplaced=sum(s.unplaced for s in stats),
        people=people,
    )


def _write_trc(args, people, tracked, *, parts=None) -> str:
    """Write ``--out`` as ``.trc``: one file per person, else one marker per track (of the
    whole recording, or of its ``parts``, a :class:`~cdog_jax.io._trc.TrcParts`). Returns the
    summary line."""
    options = dict(rate=args.fps, units=args.units, z_up=args.z_up)
    if people is not None or (parts is not None and parts.people is not None):
        stem = os.path.splitext(args.out)[0]
        inputs = {"--rig": input_files(args.rig), "--points": _point_files(args.points)}
        targets = (
            parts.people_files(args.out)
            if parts is not None
            else [f"{stem}_person{pid}.trc" for pid in person_markers(people)]
        )
        for target in targets:
            check_output(target, "--out", (".trc",), inputs)
        written = []
        _write(
            args.out,
            "--out",
            lambda: written.extend(
                parts.write_people(args.out, **options)
                if parts is not None
                else save_people_trc(args.out, people, **options)
            ),
        )
        shown = ", ".join(written[:4]) + (f", … ({len(written)} files)" if len(written) > 4 else "")
        return f"Wrote {shown or 'no file (no person was found)'}: one .trc file per person, {args.fps:g} frames/s"
    if parts is not None:
        count = []
        _write(args.out, "--out", lambda: count.append(parts.write_tracks(args.out, **options)))
        return f"Wrote {args.out}: {count[0]} marker(s), one per track, {args.fps:g} frames/s"
    markers, names = track_markers(tracked)
    _write(args.out, "--out", lambda: save_trc(args.out, markers, names, **options))
    return f"Wrote {args.out}: {len(names)} marker(s), one per track, {args.fps:g} frames/s"


def _class_shapes(det) -> dict:
    """The shapes of the classes' programs for every frame of ``det``: the most detections
    of one class in one view, and a bound on a frame's σ samples (a detection's nearest
    distance to each other view holding its class)."""
    F, M, _ = det.mask.shape
    C = int(det.classes[det.mask].max()) + 1 if det.mask.any() else 1
    frame, view, _ = np.nonzero(det.mask)
    counts = np.zeros((F, C, M), np.int64)
    np.add.at(counts, (frame, det.classes[det.mask], view), 1)
    holding = (counts > 0).sum(axis=2, keepdims=True)  # views holding the class
    samples = (counts * (holding - (counts > 0))).sum(axis=(1, 2))
    return {"min_slots": int(counts.max()), "min_samples": int(samples.max()) + 1}


def _class_counts(classed) -> np.ndarray:
    """``(F, C)`` groups of every class in every frame of a classed result."""
    valid = np.asarray(classed.association.valid)
    gc = np.asarray(classed.group_class)
    per = np.zeros((valid.shape[0], classed.num_classes), np.int64)
    f, g = np.nonzero(valid)
    np.add.at(per, (f, gc[f, g]), 1)
    return per


def _class_most(det, C: int) -> np.ndarray:
    """``(F, C)`` the most detections of every class in one view of every frame."""
    most = np.zeros((det.mask.shape[0], C), np.int64)
    for c in range(C):
        most[:, c] = ((det.classes == c) & det.mask).sum(axis=2).max(axis=1)
    return most


def _class_summary(per: np.ndarray, most: np.ndarray) -> str:
    """Groups per class per frame (``per (F, C)``) against the most detections of that class
    in one view (``most (F, C)``)."""
    C = per.shape[1]
    seen = most > 0
    fewer = int(np.count_nonzero(per[seen] < most[seen]))
    more = int(np.count_nonzero(per[seen] > most[seen]))
    return (
        f"  classes: {C}; groups per class and frame: mean {per[seen].mean() if seen.any() else 0:.2f}; "
        f"fewer than the fullest view's detections in {fewer}, more in {more} of {int(seen.sum())} (frame, class) pairs"
    )


def run_rig(args: argparse.Namespace) -> int:
    """Print the rig's description (and warnings); optionally draw it."""
    _check_paths(args, {"--plot": (args.plot, _FIGURE_EXTENSIONS)})
    rig_file, det, _ = _load(args)
    xy = mask = None
    if det is not None:
        xy, mask = det.xy[0], det.mask[0]
    text = describe_rig(
        rig_file.rig,
        xy=xy,
        mask=mask,
        image_size=rig_file.image_size,
        names=rig_file.names,
        dist=rig_file.dist,
    ).format()
    lines = [f"Rig: {args.rig}"]
    if rig_file.origin is not None:
        x, y, z = rig_file.origin
        lines.append(
            f"  note: the cameras lie far from the rig's world origin; described about their mean "
            f"centre ({x:.3f}, {y:.3f}, {z:.3f}): add it to the centres below"
        )
    lines.append(text)
    if args.plot is not None:
        # matplotlib loads only when a plot is asked for.
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # after the backend is chosen

        from ..viz import plot_rig

        ax = plot_rig(rig_file.rig, names=rig_file.names, image_size=rig_file.image_size)
        try:
            _write(args.plot, "--plot", lambda: atomic_savefig(ax.figure, args.plot, dpi=120))
        finally:
            plt.close(ax.figure)
        lines.append(f"Figure: {args.plot}")
    _emit(lines)
    return 0


def _has_lens(dist) -> bool:
    """Whether a rig file's lens does anything (a fisheye lens always does)."""
    return isinstance(dist, Fisheye) or (dist is not None and bool(np.any(dist)))

"""``cdog-jax track``: frames in on standard input, one JSON line per frame out, as each frame
is done (docs/LIVE.md): the live associator behind a detector, in a pipe.

Each input line is one frame, the object of a one-scene detections file:
``{"views": [[[x, y], …], …]}`` with optional ``"classes"`` (one list per view, ids or
names) or ``{"by_class": {name: [[[x, y], …] per view], …}}``, and an optional ``"frame"``
that is echoed back. Each output line: ``{"frame", "groups": [{"track", "class", "point",
"members": [[view, slot], …], "err_px"}, …], "sigma_px", "status"}``, written and flushed
before the next line is read. A line that cannot be used gets ``{"line": n, "error": …}``
and the stream goes on; the end of input ends the command.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from .. import LiveAssociator, method_from
from ..io import detections_from_lists, load_rig
from ..io._class_labels import views_and_labels
from ..io._errors import InputError
from ..io._keypoints import SKELETONS
from ..io._read_files import DuplicateKeyError, check_keys, unique_keys
from ..io._rig_files import FORMATS
from ._associate_command import _has_lens, refuse_camera_to_world
from ._common import _positive_int, add_method_argument

_DESCRIPTION = """Associate and track frames as they arrive: one JSON object per line on standard input
({"views": [[[x, y], ...], ...], "classes": [[c, ...], ...]}), one JSON line per frame on standard output,
flushed at once (groups with their track id, class, 3D point and members). A bad line gets an
{"line": n, "error": ...} line and the stream goes on."""


def _sigma_option(text: str) -> float | str:
    if text in ("auto", "held"):
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'must be "auto", "held" or a number of pixels > 0; got {text!r}'
        ) from None


def add_parser(subparsers) -> None:
    """Declare ``track``."""
    p = subparsers.add_parser(
        "track", help="associate and track frames streamed as JSON lines", description=_DESCRIPTION
    )
    p.add_argument("--rig", required=True, help="rig file or folder")
    p.add_argument(
        "--rig-format",
        default="auto",
        choices=("auto", *FORMATS),
        help="rig format (default: from the path)",
    )
    classes = p.add_mutually_exclusive_group()
    classes.add_argument(
        "--classes", type=_positive_int, default=None, help="the detections carry class ids 0 … N-1"
    )
    classes.add_argument(
        "--class-names",
        default=None,
        help="the detections carry these classes: comma-separated names",
    )
    classes.add_argument(
        "--keypoints",
        default=None,
        choices=tuple(SKELETONS),
        help="the classes are these keypoint types",
    )
    p.add_argument(
        "--sigma",
        type=_sigma_option,
        default="auto",
        help='detection noise σ in px; "auto" (default) estimates it in every frame; "held" '
        "estimates it until a frame's estimate is trusted, then keeps it (about a quarter "
        "less time a frame)",
    )
    add_method_argument(p)
    p.add_argument(
        "--temporal-prior",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="recover a tracked point missed in a frame near its last point (default: on)",
    )
    p.add_argument(
        "--max-gap",
        type=int,
        default=0,
        help="frames a track may go unseen and still continue (default 0)",
    )
    p.add_argument(
        "--slots",
        type=_positive_int,
        default=8,
        help="detections of one class in one view to compile for (default 8)",
    )
    p.set_defaults(func=run_track)


def run_track(args: argparse.Namespace) -> int:
    """Read frames from standard input until it ends; one output line per input line."""
    names = None
    if args.class_names is not None:
        names = tuple(n.strip() for n in args.class_names.split(","))
        if not all(names) or len(set(names)) != len(names):
            raise InputError(
                f"--class-names: expected distinct non-empty names separated by commas; got {args.class_names!r}"
            )
    elif args.keypoints is not None:
        names = SKELETONS[args.keypoints]
    if isinstance(args.sigma, float) and not (args.sigma > 0 and args.sigma < float("inf")):
        raise InputError(f"--sigma: expected a finite number > 0 (px); got {args.sigma}")
    if args.max_gap < 0:
        raise InputError(f"--max-gap: expected an integer >= 0; got {args.max_gap}")
    # Far from its world's origin (UTM-like coordinates) the rig is centred on its cameras,
    # so that float32 holds it; each line's points are put back in the file's world.
    rig_file = load_rig(args.rig, format=args.rig_format, origin="auto")
    refuse_camera_to_world(rig_file, args.rig)
    origin = (0.0, 0.0, 0.0) if rig_file.origin is None else rig_file.origin
    live = LiveAssociator(
        rig_file.rig,
        num_classes=args.classes,
        class_names=names,
        method=method_from(args.method, "cdog-jax track"),
        sigma=args.sigma,
        dist=rig_file.dist if _has_lens(rig_file.dist) else None,
        temporal_prior=args.temporal_prior,
        max_gap=args.max_gap,
        slots=args.slots,
    )
    ids = None if names is None else {n: i for i, n in enumerate(names)}
    for n, line in enumerate(sys.stdin, start=1):
        if not line.strip():
            continue
        try:
            frame_id, xy, mask, classes = _parse(line, n, live, ids)
            out = live.update(xy, mask, classes=classes)
            record = _record(out, frame_id, names, origin)
        except (ValueError, TypeError) as error:  # a bad frame: say so and go on
            message = " ".join(str(error).split())
            record = {
                "line": n,
                "error": message if message.startswith(f"line {n}") else f"line {n}: {message}",
            }
        sys.stdout.write(json.dumps(record) + "\n")
        sys.stdout.flush()
    return 0


def _parse(line: str, n: int, live, ids):
    """One input line as ``(frame id, xy (M, P, 2), mask (M, P), classes (M, P) or None)``."""
    where = f"line {n}"
    try:
        obj = json.loads(line, object_pairs_hook=unique_keys)
    except json.JSONDecodeError as error:
        raise ValueError(f"{where}: not JSON ({error.msg} at column {error.colno})") from None
    except DuplicateKeyError as e:
        raise ValueError(f'{where}: the key "{e.args[0]}" appears twice in one object') from None
    if not isinstance(obj, dict) or not ("views" in obj or "by_class" in obj):
        raise ValueError(f'{where}: expected an object {{"views": [[[x, y], …], …]}}')
    check_keys(obj, ("frame", "views", "by_class", "classes"), where)
    views, labels = views_and_labels(obj, where)
    det = detections_from_lists(views, num_views=live.rig.num_views)
    xy, mask = det.xy[0], det.mask[0]
    classes = None
    if live.classed:
        if labels is None:
            raise ValueError(
                f'{where}: the detections need classes ("classes": one list per view, or "by_class")'
            )
        classes = np.zeros(mask.shape, np.int64)
        for m, view in enumerate(labels):
            if not isinstance(view, list) or len(view) != len(views[m]):
                raise ValueError(
                    f'{where}: "classes" of view {m} must list one class per detection'
                )
            for i, label in enumerate(view):
                classes[m, i] = _class_id(
                    label, ids, live.num_classes, f"{where}, view {m}, detection {i}"
                )
    return obj.get("frame"), xy, mask, classes


def _class_id(label, ids, count: int, where: str) -> int:
    if isinstance(label, str):
        if ids is None or label not in ids:
            raise ValueError(
                f"{where}: unknown class {label!r}"
                + ("" if ids is None else f" (known: {', '.join(ids)})")
            )
        return ids[label]
    if isinstance(label, bool) or not isinstance(label, int) or not 0 <= label < count:
        raise ValueError(f"{where}: a class must be an id in [0, {count}) or a name; got {label!r}")
    return label


def _record(out, frame_id, names, origin) -> dict:
    """One frame's answer as a JSON-ready object; ``origin (3,)``: the rig file's world
    point that the rig's origin is (the points are given in the file's world)."""
    groups = []
    for g in range(len(out.groups)):
        members = [[m, int(s)] for m, s in enumerate(out.groups[g]) if s >= 0]
        group = {
            "track": int(out.track_id[g]),
            "point": [round(float(v) + float(o), 6) for v, o in zip(out.points3d[g], origin)],
            "members": members,
            "err_px": round(float(out.err_px[g]), 4),
        }
        if out.group_class is not None:
            c = int(out.group_class[g])
            group["class"] = c if names is None else names[c]
        if out.recovered[g]:
            group["recovered"] = True
        groups.append(group)
    return {
        "frame": out.frame if frame_id is None else frame_id,
        "groups": groups,
        "sigma_px": round(out.sigma_px, 4),
        "status": out.status,
    }

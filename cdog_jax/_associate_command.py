"""``cdog-jax associate`` and ``cdog-jax rig``: the user's own cameras and detections.

``associate`` reads a rig file (any format of :func:`cdog_jax.io.load_rig`) and a detections
file (:func:`cdog_jax.io.load_detections`: one scene or many frames), checks both before any
work, associates every frame in one compiled call (undistorting first when the rig carries
distortion), prints a short summary, and writes the groups (JSON, NPZ or CSV by the
extension of ``--out``) and optionally a figure of the first frame. ``rig`` prints
:meth:`cdog_jax.Rig.describe` and optionally draws the rig.

Before any work: the inputs exist and are of the right kind, the outputs can be written
and are none of the inputs (``cdog_jax/_paths.py``), the files are read and checked, and
σ is finite and at most the image diagonal (the rig file's image size, else twice the
principal point). Frames that cannot give a group (fewer than 2 views with detections)
get zero groups and a note.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

from ._cli import _positive_int, check_sigma_fits
from ._paths import check_distinct, check_input, check_output, input_files
from ._paths import write_output as _write
from .io._errors import InputError
from .io._rig_files import FORMATS

_PRESETS = ("paper", "extended", "reference")
_OUT_FORMATS = (".json", ".npz", ".csv")
_NOTES_SHOWN = 12  # notes printed in the summary; a long video can have thousands


def _sigma(text: str) -> float | str:
    if text == "auto":
        return "auto"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'must be a number of pixels >= 0 or "auto"; got {text!r}') from None
    if not (value >= 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f'must be a finite number of pixels >= 0 or "auto"; got {text!r}')
    return value


def _min_views(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 2; got {text!r}") from None
    if value < 2:
        raise argparse.ArgumentTypeError(f"must be an integer >= 2 (a group needs two views); got {text}")
    return value


def add_parsers(subparsers) -> None:
    """Declare ``associate`` and ``rig``."""
    p = subparsers.add_parser(
        "associate",
        help="associate your detections with your rig; write groups and 3D points",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--rig", required=True, help="rig file or folder")
    p.add_argument("--rig-format", default="auto", choices=("auto", *FORMATS), help="rig format (default: from the path)")
    p.add_argument("--points", required=True, help="detections file (.json or .npz): one scene or many frames")
    p.add_argument("--sigma", type=_sigma, default="auto", help='detection noise σ in px, or "auto" (default) to estimate it')
    p.add_argument("--preset", choices=_PRESETS, default="extended", help="method preset (default extended, the most accurate; paper and reference reproduce the paper and the original code)")
    p.add_argument("--min-views", type=_min_views, default=2, help="report only groups seen in at least K views (default 2)")
    p.add_argument(
        "--confidence-weights",
        action="store_true",
        help="triangulate with the detections' confidences as DLT weights (needs [x, y, c] entries)",
    )
    p.add_argument("--capacity", type=_positive_int, default=None, help="slots per view (default: the largest view); refuse if exceeded")
    p.add_argument("--out", default=None, help="write the groups: .json (members, point, BPE), .npz (arrays) or .csv (one row per 3D point)")
    p.add_argument("--plot", default=None, help="figure of the first frame's groups (.png, .pdf, .svg, .jpg)")
    p.add_argument("--batch-size", type=_positive_int, default=16, help="frames associated at once (memory bound)")
    p.set_defaults(func=run_associate)

    r = subparsers.add_parser("rig", help="describe a rig file: centres, directions, baselines, warnings", description=__doc__)
    r.add_argument("rig", help="rig file or folder")
    r.add_argument("--rig-format", default="auto", choices=("auto", *FORMATS))
    r.add_argument("--points", default=None, help="detections file: check the cameras look at their triangulated centroid")
    r.add_argument("--plot", default=None, help="figure of the camera frusta (.png, .pdf, .svg, .jpg)")
    r.set_defaults(func=run_rig)


def _check_paths(args, outputs: dict[str, tuple[str | None, tuple[str, ...]]]) -> None:
    """Inputs exist with the right kind; every output (flag → (path, extensions)) can be
    written, differs from the others and from every input file. Before any reading."""
    folder_formats = ("easyvis", "colmap", "easymocap")
    kind = "folder" if args.rig_format == "easyvis" else "file" if args.rig_format in ("json", "npz", "anipose") else "any"
    check_input(args.rig, "--rig", kind=kind)
    inputs = {"--rig": input_files(args.rig) if args.rig_format in ("auto", *folder_formats) else [args.rig]}
    if getattr(args, "points", None):
        check_input(args.points, "--points")
        inputs["--points"] = [args.points]
    check_distinct({flag: path for flag, (path, _) in outputs.items()})
    for flag, (path, extensions) in outputs.items():
        if path is not None:
            check_output(path, flag, extensions, inputs)


def _load(args):
    """Rig file and detections, checked against each other (views, image size, capacity)."""
    from .io import load_detections, load_rig

    rig_file = load_rig(args.rig, format=args.rig_format)
    detections = None
    if getattr(args, "points", None):
        detections = load_detections(
            args.points,
            num_views=rig_file.rig.num_views,
            capacity=getattr(args, "capacity", None),
            image_size=rig_file.image_size,
        )
    return rig_file, detections


def _image_diagonal(rig_file) -> tuple[float, str]:
    """The image diagonal (px) and where it comes from: the rig file's image sizes (the
    largest view), else twice the principal point of ``K / K[2,2]`` (the largest view)."""
    if rig_file.view_sizes is not None:
        w, h = np.asarray(rig_file.view_sizes, np.float64).T
        return float(np.max(np.hypot(w, h))), "image size of the rig file"
    K = np.asarray(rig_file.rig.K, np.float64)
    K = K / K[:, 2:3, 2:3]
    return float(np.max(np.hypot(2 * K[:, 0, 2], 2 * K[:, 1, 2]))), "twice the principal point; the rig file has no image size"


def run_associate(args: argparse.Namespace) -> int:
    """Load, check, associate all frames, print a summary, write the outputs."""
    import jax
    import jax.numpy as jnp

    from . import Config, Status, associate_batch
    from .graph._sigma import FALLBACK_SIGMA_PX
    from .io import save_association_csv, save_association_json, save_association_npz

    from ._cli import _FIGURE_EXTENSIONS
    from .io._detections import check_float_range

    _check_paths(args, {"--out": (args.out, _OUT_FORMATS), "--plot": (args.plot, _FIGURE_EXTENSIONS)})
    rig_file, det = _load(args)
    if args.confidence_weights and det.confidence is None:
        raise InputError(f"{args.points}: --confidence-weights: the file has no confidences (entries [x, y, c])")
    rig = rig_file.rig
    dtype = rig.K.dtype
    check_float_range(det, dtype, args.points)
    if args.sigma != "auto":
        diagonal, source = _image_diagonal(rig_file)
        check_sigma_fits(args.sigma, diagonal, f"{args.rig} ({source})")
    config = getattr(Config, args.preset)()
    F, M, P = det.mask.shape
    lines = [
        f"Rig: {args.rig} ({M} views" + (f", {rig_file.image_size[0]}×{rig_file.image_size[1]} px" if rig_file.image_size else "")
        + (", with lens distortion" if rig_file.dist is not None and np.any(rig_file.dist) else "") + ")",
        f"Detections: {args.points}: {F} frame(s), {int(det.mask.sum())} detections, at most {P} per view",
    ]
    lines += [f"  note: {n}" for n in det.notes[:_NOTES_SHOWN]]
    if len(det.notes) > _NOTES_SHOWN:
        lines.append(f"  … and {len(det.notes) - _NOTES_SHOWN} more notes")
    dist = None if rig_file.dist is None or not np.any(rig_file.dist) else jnp.asarray(rig_file.dist, dtype)
    weights = jnp.asarray(det.confidence, dtype) if args.confidence_weights else None

    t0 = time.perf_counter()
    result = associate_batch(
        rig, jnp.asarray(det.xy, dtype), jnp.asarray(det.mask), config=config, sigma=args.sigma,
        dist=dist, weights=weights, min_views=args.min_views, batch_size=args.batch_size,
    )
    result = jax.block_until_ready(result)
    elapsed = time.perf_counter() - t0
    num_groups = np.asarray(result.num_groups)
    n_views = np.asarray(result.n_views)[np.asarray(result.valid)]
    err = np.asarray(result.err_px)[np.asarray(result.valid)]
    assigned = int((np.asarray(result.labels) >= 0).sum())
    lines += [
        f"Associated with {args.preset}() (σ {'estimated' if args.sigma == 'auto' else f'= {args.sigma:g} px'}, "
        f"min views {args.min_views}) in {elapsed:.2f} s including compilation",
        f"  3D points: {int(num_groups.sum())} ({num_groups.min()}–{num_groups.max()} per frame)" if F > 1 else f"  3D points: {int(num_groups.sum())}",
        f"  detections assigned: {assigned} of {int(det.mask.sum())}",
    ]
    if n_views.size:
        counts = np.bincount(n_views, minlength=M + 1)
        lines.append("  views per point: " + ", ".join(f"{k}: {counts[k]}" for k in range(2, M + 1) if counts[k]))
        lines.append(
            f"  reprojection error err_px (mean distance over a group's views): mean {err.mean():.2f} px, "
            f"median {np.median(err):.2f}, max {err.max():.2f}"
        )
    fallback = np.flatnonzero(np.asarray(result.status) & int(Status.SIGMA_FALLBACK))
    lines.append(
        "  σ used: " + ", ".join(f"{s:.2f}" for s in np.asarray(result.sigma_px)[:8]) + (" …" if F > 8 else "") + " px"
        + (f" (the fallback {FALLBACK_SIGMA_PX:g} px in {len(fallback)} of {F} frame(s), e.g. frame {fallback[0]}: "
           "too little evidence to estimate σ; pass --sigma)" if fallback.size else "")
    )
    from ._status import status_messages

    status = np.asarray(result.status).reshape(-1)
    for flag in Status:  # the σ fallback is said on the line above
        hit = int(np.count_nonzero(status & int(flag))) if flag not in (Status.OK, Status.SIGMA_FALLBACK) else 0
        if hit:
            lines.append(f"  warning: {hit} of {F} frame(s): {status_messages(int(flag))[0]}")
    if args.out is not None:
        one = F == 1 and not det.frames
        frame = (lambda a: a[0]) if one else (lambda a: a)
        assoc = jax.tree_util.tree_map(frame, result)
        xy, mask = frame(det.xy), frame(det.mask)
        conf = None if det.confidence is None else frame(det.confidence)
        ext = os.path.splitext(args.out)[1].lower()
        if ext == ".json":
            _write(args.out, "--out", lambda: save_association_json(args.out, assoc, xy, mask, confidence=conf))
        elif ext == ".npz":
            _write(args.out, "--out", lambda: save_association_npz(args.out, assoc, xy=xy, mask=mask, confidence=conf))
        else:
            _write(args.out, "--out", lambda: save_association_csv(args.out, assoc))
        lines.append(f"Wrote {args.out}")
    if args.plot is not None:
        from ._plot import plot_association
        from .synthetic import intrinsics_image_size

        first = jax.tree_util.tree_map(lambda a: a[0], result)
        size = rig_file.image_size or intrinsics_image_size(rig.K)
        _write(args.plot, "--plot", lambda: plot_association(
            rig, det.xy[0], det.mask[0], first, image_size=size, title=f"{args.points}, frame 0", path=args.plot
        ))  # fmt: skip
        lines.append(f"Figure: {args.plot}")
    from ._cli import _emit

    _emit(lines)
    return 0


def run_rig(args: argparse.Namespace) -> int:
    """Print the rig's description (and warnings); optionally draw it."""
    from ._cli import _FIGURE_EXTENSIONS, _emit

    _check_paths(args, {"--plot": (args.plot, _FIGURE_EXTENSIONS)})
    rig_file, det = _load(args)
    xy = mask = None
    if det is not None:
        xy, mask = det.xy[0], det.mask[0]
    text = rig_file.rig.describe(
        xy=xy, mask=mask, image_size=rig_file.image_size, names=rig_file.names, dist=rig_file.dist
    )
    lines = [f"Rig: {args.rig}", text]
    if args.plot is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from ._rig_plot import plot_rig

        from .io._atomic import atomic_savefig

        ax = plot_rig(rig_file.rig, names=rig_file.names, image_size=rig_file.image_size)
        try:
            _write(args.plot, "--plot", lambda: atomic_savefig(ax.figure, args.plot, dpi=120))
        finally:
            plt.close(ax.figure)
        lines.append(f"Figure: {args.plot}")
    _emit(lines)
    return 0

"""EasyMocap ``intri.yml`` + ``extri.yml`` rigs (OpenCV FileStorage YAML) (docs/CONVENTIONS.md §3).

``intri.yml``: ``names`` (a list of camera names), ``K_<name>`` (3×3), ``dist_<name>``
(1×5 or 5×1; 4 coefficients get ``k3 = 0``) and optional ``H_<name>``, ``W_<name>`` (the
image height and width, integers). ``extri.yml``: ``R_<name>`` (3×1 Rodrigues vector, the
rotation EasyMocap reads), ``Rot_<name>`` (3×3, used only without ``R_<name>``; when both
are given they must agree) and ``T_<name>`` (3×1). Matrices are ``!!opencv-matrix`` maps with ``rows``, ``cols``, ``dt``
and ``data: [...]``.

Convention (EasyMocap's ``read_camera``): world→camera, ``X_cam = Rot X_world + T`` with
``Rot = cv2.Rodrigues(R)`` (axis × angle in radians); OpenCV camera axes (x right, y
down, z forward) and pixels (centre of the top-left pixel at ``(0, 0)``); ``dist`` is
OpenCV's ``(k1, k2, p1, p2, k3)``.

Only the subset of YAML that OpenCV and EasyMocap write is parsed (no PyYAML): top-level
``key: value`` lines, ``!!opencv-matrix`` maps (``data`` may span lines), block (``- x``)
and flow (``[x, y]``) lists of scalars, ``#`` comments, ``%YAML`` and ``---`` lines.
An unquoted scalar is kept as written (``- 01`` is the name ``"01"``).
"""

from __future__ import annotations

import os
import re
from typing import Any, NamedTuple

import numpy as np

from .._expect import PATH, expect_args
from ..geometry._camera import Rig
from ..geometry._distortion import Fisheye
from ._atomic import atomic_write
from ._errors import read_text
from ._rig_files import PathLike, _Views
from ._rig_values import (
    _check_dist,
    _check_names,
    _check_view_sizes,
    _host_rig,
    _K_over_K22,
    _opencv_dist,
)
from ._rotations import rodrigues_from_rotation, rotation_from_rodrigues

_TOP_KEY = re.compile(r"([A-Za-z_][\w\- ]*?)\s*:(?:\s+(.*))?$")
_ROT_TOL = 1e-4  # |Rot - Rodrigues(R)|: both written by one tool, so only rounding apart


class _Matrix(NamedTuple):
    data: np.ndarray  # (rows, cols) float64
    line: int


class _Entry(NamedTuple):
    value: Any  # _Matrix, list[str] or str
    line: int


def read_easymocap(path: str) -> _Views:
    """Read EasyMocap ``intri.yml`` + ``extri.yml``: a folder holding both, or the path of
    one of them (the module docstring has the convention).

    Views follow ``names`` of ``intri.yml`` (``extri.yml``'s, when given, must be the same).
    ``dist_<name>`` (or ``D_<name>``) may be missing: zeros. The image size of a camera is
    ``(W_<name>, H_<name>)`` when both are given (all cameras or none).
    """
    folder = os.path.dirname(path) if os.path.isfile(path) else path
    intri_file, extri_file = os.path.join(folder, "intri.yml"), os.path.join(folder, "extri.yml")
    for file in (intri_file, extri_file):
        if not os.path.isfile(file):
            raise ValueError(f"{path}: missing {file} (an EasyMocap rig is intri.yml + extri.yml)")
    intri, extri = _parse(intri_file), _parse(extri_file)
    if "names" not in intri:
        raise ValueError(f'{intri_file}: missing key "names" (the list of camera names)')
    names = _names(intri["names"], intri_file)
    if "names" in extri and _names(extri["names"], extri_file) != names:
        raise ValueError(
            f'{extri_file}, line {extri["names"].line}: key "names" {list(_names(extri["names"], extri_file))} '
            f"differs from {intri_file}'s {list(names)}"
        )
    if not names:
        raise ValueError(
            f'{intri_file}, line {intri["names"].line}: key "names" is empty (zero cameras)'
        )
    if len(set(names)) != len(names):
        raise ValueError(
            f'{intri_file}, line {intri["names"].line}: key "names" repeats a camera: {list(names)}'
        )
    Ks, Rs, ts, dists, sizes = [], [], [], [], []
    for m, name in enumerate(names):
        cam = f"view {m} (camera {name!r})"
        Ks.append(_matrix(intri, f"K_{name}", intri_file, cam, (3, 3)))
        sizes.append(_size(intri, name, intri_file, cam))
        dist_key = next((k for k in (f"dist_{name}", f"D_{name}") if k in intri), None)
        if dist_key is None:
            dists.append(None)
        else:
            d = _matrix(intri, dist_key, intri_file, cam, None)
            where = f'{intri_file}, line {intri[dist_key].line}: {cam}, key "{dist_key}"'
            if min(d.shape) != 1:
                raise ValueError(
                    f"{where}: expected a 1×N or N×1 matrix; got {d.shape[0]}×{d.shape[1]}"
                )
            dists.append(_opencv_dist(d, where))
        rvec_key, rot_key = f"R_{name}", f"Rot_{name}"
        if rot_key not in extri and rvec_key not in extri:
            raise ValueError(f'{extri_file}: {cam}: missing key "{rvec_key}" (or "{rot_key}")')
        if rvec_key in extri:  # EasyMocap's read_camera uses R_ (Rodrigues) and ignores Rot_
            R = rotation_from_rodrigues(_matrix(extri, rvec_key, extri_file, cam, (3, 1)))
            if rot_key in extri:
                R_rot = _matrix(extri, rot_key, extri_file, cam, (3, 3))
                if np.abs(R_rot - R).max() > _ROT_TOL:
                    raise ValueError(
                        f'{extri_file}, line {extri[rot_key].line}: {cam}: "{rot_key}" and the rotation of '
                        f'"{rvec_key}" (line {extri[rvec_key].line}) differ by {np.abs(R_rot - R).max():.3g} '
                        f'(expected agreement within {_ROT_TOL:g}; EasyMocap uses "{rvec_key}")'
                    )
        else:
            R = _matrix(extri, rot_key, extri_file, cam, (3, 3))
        Rs.append(R)
        ts.append(_matrix(extri, f"T_{name}", extri_file, cam, (3, 1))[:, 0])
    dist = None
    if any(d is not None for d in dists):
        dist = np.stack([np.zeros(5) if d is None else d for d in dists])
    view_sizes = None
    if any(s is not None for s in sizes):
        missing = [m for m, s in enumerate(sizes) if s is None]
        if missing:
            raise ValueError(
                f'{intri_file}: view {missing[0]} (camera {names[missing[0]]!r}): missing "H_{names[missing[0]]}" / '
                f'"W_{names[missing[0]]}" (other cameras give their image size)'
            )
        view_sizes = np.array(sizes, dtype=np.int64)
    return _Views(np.stack(Ks), np.stack(Rs), np.stack(ts), view_sizes, dist, names)


def _size(intri: dict[str, _Entry], name: str, file: str, cam: str) -> tuple[int, int] | None:
    """``(W_<name>, H_<name>)``, positive integers, or ``None`` when neither is given."""
    keys = (f"W_{name}", f"H_{name}")
    given = [k in intri for k in keys]
    if not any(given):
        return None
    if not all(given):
        raise ValueError(
            f'{file}: {cam}: "{keys[given.index(True)]}" without "{keys[given.index(False)]}"'
        )
    values = []
    for key in keys:
        entry = intri[key]
        value = entry.value.data.reshape(-1) if isinstance(entry.value, _Matrix) else entry.value
        text = str(value[0] if isinstance(value, np.ndarray) and value.size == 1 else value)
        try:
            number = float(text)
        except ValueError:
            number = float("nan")
        if not (number >= 1 and number.is_integer()):
            raise ValueError(
                f'{file}, line {entry.line}: {cam}, key "{key}": expected a positive integer; got {text!r}'
            )
        values.append(int(number))
    return values[0], values[1]


def _names(entry: _Entry, file: str) -> tuple[str, ...]:
    if not isinstance(entry.value, list):
        raise ValueError(
            f'{file}, line {entry.line}: key "names": expected a list of strings; got {entry.value!r}'
        )  # noqa: TRY004
    return tuple(entry.value)


def _matrix(
    entries: dict[str, _Entry], key: str, file: str, cam: str, shape: tuple[int, int] | None
) -> np.ndarray:
    """``entries[key]`` as a float64 matrix of ``shape`` (a vector ``(3, 1)`` may be ``(1, 3)``)."""
    if key not in entries:
        raise ValueError(f'{file}: {cam}: missing key "{key}"')
    entry = entries[key]
    where = f'{file}, line {entry.line}: {cam}, key "{key}"'
    if not isinstance(entry.value, _Matrix):
        raise ValueError(f"{where}: expected an !!opencv-matrix; got {entry.value!r}")  # noqa: TRY004
    a = entry.value.data
    if shape == (3, 1) and a.shape == (1, 3):
        a = a.T
    if shape is not None and a.shape != shape:
        raise ValueError(
            f"{where}: expected a {shape[0]}×{shape[1]} matrix; got {a.shape[0]}×{a.shape[1]}"
        )
    return a


def _parse(file: str) -> dict[str, _Entry]:
    """The top-level entries of an OpenCV FileStorage YAML file (the subset of the module
    docstring)."""
    lines = read_text(file).splitlines()
    entries: dict[str, _Entry] = {}
    i = 0
    while i < len(lines):
        line, lineno = lines[i], i + 1
        i += 1
        stripped = line.strip()
        if not stripped or stripped.startswith(("#", "%")) or stripped in ("---", "..."):
            continue
        match = _TOP_KEY.match(line)
        if line[0].isspace() or not match:
            raise ValueError(
                f"{file}, line {lineno}: expected a top-level 'key: value' line; got {line!r}"
            )
        key, rest = match.group(1), (match.group(2) or "").strip()
        body = []  # the indented lines (or a "- item" list) that belong to this key
        while i < len(lines) and (
            lines[i][:1].isspace() or lines[i].startswith("-") or not lines[i].strip()
        ):
            if lines[i].strip() and not lines[i].strip().startswith("#"):
                body.append(lines[i].strip())
            i += 1
        if key in entries:
            raise ValueError(
                f'{file}, line {lineno}: key "{key}" defined twice (also on line {entries[key].line})'
            )
        entries[key] = _Entry(
            _value(rest, body, f'{file}, line {lineno}, key "{key}"', lineno), lineno
        )
    return entries


def _value(rest: str, body: list[str], where: str, lineno: int) -> Any:
    if rest.startswith(("!!opencv-matrix", "!<tag:yaml.org,2002:opencv-matrix>")):
        text = " ".join([rest.split(None, 1)[1] if " " in rest else ""] + body)
        fields = {}
        for name in ("rows", "cols"):
            match = re.search(rf"\b{name}\s*:\s*([0-9]+)", text)
            if not match:
                raise ValueError(f"{where}: !!opencv-matrix without {name!r}")
            fields[name] = int(match.group(1))
        match = re.search(r"\bdata\s*:\s*\[(.*?)\]", text)
        if not match:
            raise ValueError(f"{where}: !!opencv-matrix without 'data: [...]'")
        items = [x for x in re.split(r"[,\s]+", match.group(1)) if x]
        try:
            data = np.array([float(x) for x in items], dtype=np.float64)
        except ValueError:
            raise ValueError(
                f"{where}: 'data' must hold numbers; got [{match.group(1).strip()}]"
            ) from None
        if not np.isfinite(data).all():
            raise ValueError(f"{where}: 'data' has non-finite entries")
        rows, cols = fields["rows"], fields["cols"]
        if data.size != rows * cols:
            raise ValueError(
                f"{where}: rows × cols = {rows} × {cols} but 'data' holds {data.size} numbers"
            )
        return _Matrix(data.reshape(rows, cols), lineno)
    if not rest and body and all(b.startswith("-") for b in body):
        return [_scalar(b[1:].strip()) for b in body]
    if rest.startswith("["):
        text = " ".join([rest] + body).strip()
        if not text.endswith("]"):
            raise ValueError(f"{where}: unterminated list {text!r}")
        return [_scalar(x.strip()) for x in text[1:-1].split(",") if x.strip()]
    if not rest:
        return " ".join(body)  # a nested map or other structure: kept as text, not used
    return _scalar(rest)


def _scalar(text: str) -> str:
    """A YAML scalar as a string: quotes removed (with ``\\"``, ``\\\\`` and ``''`` unescaped)."""
    if len(text) >= 2 and text[0] == text[-1] == '"':
        return re.sub(r"\\(.)", r"\1", text[1:-1])
    if len(text) >= 2 and text[0] == text[-1] == "'":
        return text[1:-1].replace("''", "'")
    return text


def save_rig_easymocap(
    folder: PathLike, rig: Rig, *, dist: Any = None, names: Any = None, image_size: Any = None
) -> None:
    """Write ``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as EasyMocap ``intri.yml`` and
    ``extri.yml`` in ``folder`` (created if needed), in OpenCV FileStorage YAML.

    ``intri.yml``: ``names``, ``K_<name> = K / K[2,2]`` (same projection; OpenCV assumes
    ``K[2,2] = 1`` and ignores the skew ``K[0,1]``, which is written all the same) and
    ``dist_<name>`` (1×5, ``dist (M, 5)``, zeros when ``None``; EasyMocap has no fisheye
    model), and ``H_<name>``, ``W_<name>`` when ``image_size`` (``(w, h)`` or ``(M, 2)``)
    is given. ``extri.yml``: ``names``,
    ``R_<name>`` (3×1 Rodrigues), ``Rot_<name>`` (3×3) and ``T_<name>`` (3×1). ``names``
    (default ``"{m:02d}"``) must be OpenCV keys: letters, digits, ``_`` and ``-``. Numbers
    are written with float64 ``repr``.
    """
    expect_args("save_rig_easymocap", folder=(folder, PATH), rig=(rig, Rig))
    K, R, t = _host_rig(rig)
    M = K.shape[0]
    K = _K_over_K22(K)
    dist = _check_dist(dist, M)
    if isinstance(dist, Fisheye):
        raise ValueError(
            "save_rig: EasyMocap has no fisheye lens model; write another format or undistort first"
        )
    dist = np.zeros((M, 5)) if dist is None else dist
    sizes = _check_view_sizes(image_size, M)
    names = _check_names(
        names,
        M,
        "{:02d}",
        r"[A-Za-z0-9_\-]+",
        "EasyMocap camera names must be letters, digits, _ or -",
    )
    head = "%YAML:1.0\n---\nnames:\n" + "".join(f'   - "{n}"\n' for n in names)
    intri, extri = [head], [head]
    for m, name in enumerate(names):
        intri += [_yaml_matrix(f"K_{name}", K[m]), _yaml_matrix(f"dist_{name}", dist[m][None, :])]
        if sizes is not None:
            intri += [f"H_{name}: {int(sizes[m, 1])}\n", f"W_{name}: {int(sizes[m, 0])}\n"]
        rvec = rodrigues_from_rotation(R[m])
        extri += [
            _yaml_matrix(f"R_{name}", rvec[:, None]),
            _yaml_matrix(f"Rot_{name}", R[m]),
            _yaml_matrix(f"T_{name}", t[m][:, None]),
        ]
    folder = os.fspath(folder)
    os.makedirs(folder, exist_ok=True)
    for file, parts in (("intri.yml", intri), ("extri.yml", extri)):
        with atomic_write(os.path.join(folder, file), "w") as f:
            f.write("".join(parts))


def _yaml_matrix(key: str, a: np.ndarray) -> str:
    data = ", ".join(repr(float(x)) for x in a.reshape(-1))
    return f"{key}: !!opencv-matrix\n   rows: {a.shape[0]}\n   cols: {a.shape[1]}\n   dt: d\n   data: [ {data} ]\n"

"""Reading and writing force traces (the CSV format of ``data/README.md``).

A trace file is plain UTF-8 text (a leading byte-order mark is accepted)::

    # radius_m: 2.0e-3          <- required: sphere (or reduced, eq 24) radius R [m]
    # poisson_ratio: 0.5        <- optional; any other "# key: value" line is kept as metadata
    # drive: force              <- optional: travel (default), spring, force (load control)
    # stiffness_N_m: 5000       <- optional: the load cell's stiffness (then drive spring)
    time_s,displacement_m,force_N
    0.0,0.0,0.0012
    ...

* ``time_s`` strictly increasing [s];
* ``displacement_m`` indenter travel d(t) toward the substrate since the first row [m]
  (positive = toward it; the gap is z(t) = z0 - d(t), z0 unknown);
* ``force_N`` normal force [N], positive when the film/substrate pushes back.

Every malformed input raises :class:`TraceError` (a ``ValueError``) naming the file, the line
(1-based) and, for cell errors, the column. Scales the thin-film model cannot describe (travel
beyond ``MAX_TRAVEL_OVER_RADIUS`` R, |force| above ``MAX_FORCE_N``, R outside ``RADIUS_RANGE_M``)
are refused the same way, with the likely unit mistake (:func:`check_scales`).

Reading is numpy-fast: the numeric block goes through ``numpy.loadtxt``; only a file that it
rejects is parsed again line by line, to name the offending line and column.
"""

from __future__ import annotations

import codecs
import math
import os
import re
import warnings
from array import array
from typing import NamedTuple

import numpy as np

from lubjax._files import MAX_TRAVEL_OVER_RADIUS, write_text

COLUMNS = ("time_s", "displacement_m", "force_N")
MIN_ROWS = 10
#: Larger files are refused (a 200 MB trace reads in a few seconds; decimate anything bigger).
MAX_FILE_BYTES = 1 << 30
#: Sphere radii outside this range [m] are refused (a radius in mm reads as metres: R > 1 m).
RADIUS_RANGE_M = (1e-7, 1.0)
#: |force| above this [N] is refused: far beyond a soft lubricated contact (a wrong unit).
MAX_FORCE_N = 1e3
POISSON_RANGE = (-1.0, 0.5)  # (-1, 0.5]

_EOL = re.compile(r"\r\n|\r|\n")


class TraceError(ValueError):
    """A trace that cannot be used; the message names the file, line and column."""


class Trace(NamedTuple):
    """One measured (or synthetic) relaxation trace in SI units.

    Attributes:
        time: sample times t_k [s], strictly increasing.
        displacement: indenter travel d(t_k) toward the substrate [m].
        force: normal force F(t_k) [N].
        radius: sphere (or reduced) radius R [m].
        metadata: the ``# key: value`` header lines (values as strings), ``radius_m`` included.
        name: where the trace came from (file path or a label).
    """

    time: np.ndarray
    displacement: np.ndarray
    force: np.ndarray
    radius: float
    metadata: dict
    name: str = ""

    def meta_float(self, key: str, default=None):
        """A metadata value as a float (``default`` if absent or not a number)."""
        try:
            return float(self.metadata[key])
        except (KeyError, TypeError, ValueError):
            return default


def _positive_radius(value, where: str) -> float:
    try:
        r = float(value)
    except (TypeError, ValueError):
        raise TraceError(
            f"{where}: radius_m must be a positive number in metres, got {value!r}"
        ) from None
    if not (math.isfinite(r) and r > 0):
        raise TraceError(f"{where}: radius_m must be finite and > 0 (metres), got {value!r}")
    lo, hi = RADIUS_RANGE_M
    if not lo <= r <= hi:
        hint = "millimetres" if r > hi else "another unit"
        raise TraceError(
            f"{where}: radius_m = {r:g} m is outside [{lo:g}, {hi:g}] m, the sphere radii the "
            f"model is meant for: is it in {hint} instead of metres?"
        )
    return r


def _poisson(value, where: str) -> float:
    lo, hi = POISSON_RANGE
    try:
        nu = float(value)
    except (TypeError, ValueError):
        nu = math.nan
    if not (math.isfinite(nu) and lo < nu <= hi):
        raise TraceError(f"{where}: poisson_ratio must be a number in (-1, 0.5], got {value!r}")
    return nu


#: Values of the ``# drive:`` header key (fitting._model.DRIVES).
DRIVE_VALUES = ("travel", "spring", "force")


def _check_model_keys(metadata: dict, where) -> None:
    """``drive`` one of DRIVE_VALUES and ``stiffness_N_m`` a positive number; ``where(key)``
    names the place (file and line)."""
    if "drive" in metadata and metadata["drive"] not in DRIVE_VALUES:
        raise TraceError(
            f"{where('drive')}: drive must be one of {', '.join(DRIVE_VALUES)} (force: load "
            f"control, the displacement is the response), got {metadata['drive']!r}"
        )
    if "stiffness_N_m" in metadata:
        try:
            k = float(metadata["stiffness_N_m"])
        except (TypeError, ValueError):
            k = math.nan
        if not (math.isfinite(k) and k > 0):
            raise TraceError(
                f"{where('stiffness_N_m')}: stiffness_N_m (the instrument's load-cell "
                f"stiffness) must be a finite number > 0 in N/m, got {metadata['stiffness_N_m']!r}"
            )


def check_scales(trace: Trace) -> None:
    """TraceError unless the trace's scales fit the thin-film model (see module docstring).

    The model needs travel d ≪ R (and gap z0 ≪ R): a trace whose |displacement| exceeds
    ``MAX_TRAVEL_OVER_RADIUS`` R is refused, as is |force| > ``MAX_FORCE_N``. Both catch a
    column in the wrong unit (mm or μm for m, mN for N) that would otherwise fit to nonsense.
    """
    name = trace.name or "trace"
    r = float(trace.radius)
    travel = float(np.max(np.abs(trace.displacement))) if trace.displacement.size else 0.0
    if travel > MAX_TRAVEL_OVER_RADIUS * r:
        raise TraceError(
            f"{name}: column displacement_m: the travel reaches {travel:.4g} m, "
            f"{travel / r:.3g} times the radius R = {r:g} m; the thin-film model needs travel "
            f"≪ R and refuses more than {MAX_TRAVEL_OVER_RADIUS:g} R. Is displacement_m in "
            "millimetres or micrometres instead of metres?"
        )
    peak = float(np.max(np.abs(trace.force))) if trace.force.size else 0.0
    if peak > MAX_FORCE_N:
        raise TraceError(
            f"{name}: column force_N: |force| reaches {peak:.4g} N, above {MAX_FORCE_N:g} N, "
            "far beyond a soft lubricated contact. Is force_N in another unit (mN, μN)?"
        )


def make_trace(time, displacement, force, radius, metadata=None, name: str = "") -> Trace:
    """Build a validated :class:`Trace` from arrays (same checks as the file reader)."""
    label = name or "trace"
    arrays = []
    for col, values in zip(COLUMNS, (time, displacement, force), strict=True):
        try:
            a = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TraceError(f"{label}: column {col!r} is not numeric ({exc})") from None
        if a.ndim != 1:
            raise TraceError(f"{label}: column {col!r} must be 1-D, got shape {a.shape}")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise TraceError(
                f"{label}: row {bad[0]}, column {col!r}: value {a[bad[0]]} is not finite"
            )
        arrays.append(a)
    t, d, f = arrays
    if not (t.size == d.size == f.size):
        raise TraceError(f"{label}: columns have different lengths {t.size}, {d.size}, {f.size}")
    if t.size < MIN_ROWS:
        raise TraceError(f"{label}: need at least {MIN_ROWS} data rows, got {t.size}")
    step = np.flatnonzero(np.diff(t) <= 0)
    if step.size:
        k = step[0] + 1
        raise TraceError(
            f"{label}: row {k}, column 'time_s': time {float(t[k])!r} does not increase "
            f"(previous {float(t[k - 1])!r})"
        )
    meta = dict(metadata or {})
    r = _positive_radius(radius, label)
    if "poisson_ratio" in meta:
        _poisson(meta["poisson_ratio"], label)
    _check_model_keys(meta, lambda key: label)
    meta.setdefault("radius_m", repr(r))
    trace = Trace(t, d, f, r, meta, name)
    check_scales(trace)
    return trace


class _Header(NamedTuple):
    metadata: dict
    radius: float
    columns: list
    line: int  # of the header row


def _read_header(lines, name: str) -> _Header:
    """Consume ``(lineno, text)`` pairs up to and including the header row; check it and the
    metadata (duplicate keys, radius_m, poisson_ratio)."""
    metadata: dict[str, str] = {}
    meta_line: dict[str, int] = {}
    for lineno, raw in lines:
        if "\x00" in raw:
            raise TraceError(
                f"{name}: line {lineno}: NUL byte: a binary file (or UTF-16 text), not a UTF-8 CSV"
            )
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            body = line[1:].strip()
            if ":" in body:
                key, value = body.split(":", 1)
                key = key.strip()
                if not key:
                    raise TraceError(f"{name}: line {lineno}: empty metadata key in {raw!r}")
                if key in metadata:
                    raise TraceError(
                        f"{name}: lines {meta_line[key]} and {lineno} both give '# {key}:' "
                        f"({metadata[key]!r}, {value.strip()!r}); keep one"
                    )
                metadata[key] = value.strip()
                meta_line[key] = lineno
            continue  # a plain comment
        cells = [c.strip() for c in line.split(",")]
        seen = set()
        for j, col in enumerate(cells, start=1):
            if col not in COLUMNS:
                raise TraceError(
                    f"{name}: line {lineno}, column {j}: unknown column {col!r} "
                    f"(expected {', '.join(COLUMNS)})"
                )
            if col in seen:
                raise TraceError(f"{name}: line {lineno}, column {j}: duplicate column {col!r}")
            seen.add(col)
        missing = [c for c in COLUMNS if c not in seen]
        if missing:
            raise TraceError(
                f"{name}: line {lineno}: missing column(s) {', '.join(missing)} "
                f"(header is {line!r})"
            )
        if "radius_m" not in metadata:
            raise TraceError(
                f"{name}: missing '# radius_m: <metres>' header line (the sphere radius R is "
                "required)"
            )
        radius = _positive_radius(metadata["radius_m"], f"{name}: line {meta_line['radius_m']}")
        if "poisson_ratio" in metadata:
            _poisson(metadata["poisson_ratio"], f"{name}: line {meta_line['poisson_ratio']}")
        _check_model_keys(metadata, lambda key: f"{name}: line {meta_line[key]}")
        return _Header(metadata, radius, cells, lineno)
    raise TraceError(f"{name}: no header row (expected {','.join(COLUMNS)})")


def _finish(name: str, head: _Header, data: np.ndarray) -> Trace:
    cols = [np.ascontiguousarray(data[:, head.columns.index(c)]) for c in COLUMNS]
    trace = Trace(*cols, head.radius, head.metadata, name)
    check_scales(trace)
    return trace


def _iter_lines(text: str):
    """``(lineno, line)`` for each line (universal newlines), without copying ``text``."""
    pos, n, lineno = 0, len(text), 0
    while pos < n:
        m = _EOL.search(text, pos)
        lineno += 1
        if m is None:
            yield lineno, text[pos:]
            return
        yield lineno, text[pos : m.start()]
        pos = m.end()


def parse_trace(text: str, name: str = "<string>") -> Trace:
    """Parse the CSV text of a trace (see module docstring). Errors name ``name:line:column``."""
    if text.startswith("\ufeff"):
        text = text[1:]
    lines = _iter_lines(text)
    head = _read_header(lines, name)
    ncol = len(head.columns)
    values = array("d")
    row_lines = array("q")
    for lineno, raw in lines:
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            raise TraceError(
                f"{name}: line {lineno}: '# key: value' lines must come before the header row"
            )
        cells = line.split(",")
        if len(cells) != ncol:
            raise TraceError(
                f"{name}: line {lineno}: expected {ncol} cells ({', '.join(head.columns)}), "
                f"got {len(cells)}"
            )
        for j, (col, cell) in enumerate(zip(head.columns, cells, strict=True), start=1):
            try:
                v = float(cell)
            except ValueError:
                raise TraceError(
                    f"{name}: line {lineno}, column {j} ({col}): {cell.strip()!r} is not a number"
                ) from None
            if not math.isfinite(v):
                raise TraceError(
                    f"{name}: line {lineno}, column {j} ({col}): {cell.strip()!r} is not finite"
                )
            values.append(v)
        row_lines.append(lineno)
    if len(row_lines) < MIN_ROWS:
        raise TraceError(
            f"{name}: need at least {MIN_ROWS} data rows after the header (line {head.line}), "
            f"got {len(row_lines)}"
        )
    data = np.frombuffer(values, dtype=np.float64).reshape(-1, ncol)
    j = head.columns.index("time_s")
    t = data[:, j]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = bad[0] + 1
        raise TraceError(
            f"{name}: line {row_lines[k]}, column {j + 1} (time_s): time {float(t[k])!r} is not "
            f"greater than the previous row's {float(t[k - 1])!r} (must increase)"
        )
    return _finish(name, head, data)


def _decode(data: bytes, name: str) -> str:
    """UTF-8 text (a leading BOM is kept: parse_trace drops it); TraceError naming the line of
    the first bad byte."""
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        raise TraceError(f"{name}: line 1: the file is UTF-16 text; save it as UTF-8 (CSV UTF-8)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = len(_EOL.findall(data[: exc.start].decode("utf-8", "replace"))) + 1
        raise TraceError(
            f"{name}: line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x}); a binary file, "
            "or text in another encoding: save it as UTF-8 (CSV UTF-8)"
        ) from None


def _read_fast(path: str) -> Trace | None:
    """The header line by line, the numeric block by ``numpy.loadtxt``; None if the block (or an
    encoding error) needs the line-by-line parser to name what is wrong."""
    with open(path, encoding="utf-8-sig", newline=None) as fh:
        lines = ((n, s.rstrip("\n")) for n, s in enumerate(iter(fh.readline, ""), start=1))
        try:
            head = _read_header(lines, path)
        except UnicodeDecodeError:
            return None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "input contained no data"
                data = np.loadtxt(fh, delimiter=",", comments=None, ndmin=2, dtype=np.float64)
        except ValueError:  # UnicodeDecodeError included
            return None
    if data.shape[1] != len(head.columns) or data.shape[0] < MIN_ROWS:
        return None
    t = data[:, head.columns.index("time_s")]
    if not (np.isfinite(data).all() and np.all(np.diff(t) > 0)):
        return None
    return _finish(path, head, data)


def read_trace(path) -> Trace:
    """Read a trace CSV file (see module docstring for the format)."""
    path = os.fspath(path)
    try:
        if os.path.isdir(path):
            raise TraceError(f"{path}: is a folder, not a trace file")
        size = os.path.getsize(path)
        if size > MAX_FILE_BYTES:
            raise TraceError(
                f"{path}: the file is {size / 1e9:.3g} GB; traces over "
                f"{MAX_FILE_BYTES / 1e9:.3g} GB are refused (decimate it)"
            )
        trace = _read_fast(path)
        if trace is None:  # something is wrong or unusual: the careful parser names it
            with open(path, "rb") as fh:
                raw = fh.read()
            trace = parse_trace(_decode(raw, path), name=path)
    except OSError as exc:
        raise TraceError(f"{path}: cannot read trace file ({exc.strerror or exc})") from None
    return trace


def format_trace(trace: Trace) -> str:
    """The CSV text of a trace: metadata lines, header, rows (round-trips through parse_trace)."""
    lines = []
    meta = dict(trace.metadata)
    meta.setdefault("radius_m", repr(float(trace.radius)))
    for key, value in meta.items():
        if "\n" in str(value) or "\r" in str(value) or ":" in key or not key.strip():
            raise TraceError(f"metadata key/value not representable on one line: {key!r}")
        lines.append(f"# {key}: {value}")
    lines.append(",".join(COLUMNS))
    for t, d, f in zip(trace.time, trace.displacement, trace.force, strict=True):
        lines.append(f"{t:.6g},{d:.7e},{f:.6e}")
    return "\n".join(lines) + "\n"


def write_trace(path, trace: Trace) -> None:
    """Write a trace as CSV, atomically (creates parent folders)."""
    write_text(path, format_trace(trace))

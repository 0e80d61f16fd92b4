"""Reading and writing force traces (the CSV format of ``data/README.md``).

A trace file is plain text::

    # radius_m: 2.0e-3          <- required: sphere (or reduced, eq 24) radius R [m]
    # poisson_ratio: 0.5        <- optional; any other "# key: value" line is kept as metadata
    time_s,displacement_m,force_N
    0.0,0.0,0.0012
    ...

* ``time_s`` strictly increasing [s];
* ``displacement_m`` indenter travel d(t) toward the substrate since the first row [m]
  (positive = toward it; the gap is z(t) = z0 - d(t), z0 unknown);
* ``force_N`` normal force [N], positive when the film/substrate pushes back.

Every malformed input raises ``ValueError`` naming the file, the line (1-based) and, for cell
errors, the column.
"""

from __future__ import annotations

import math
import os
from typing import NamedTuple

import numpy as np

COLUMNS = ("time_s", "displacement_m", "force_N")
MIN_ROWS = 10


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
        raise ValueError(
            f"{where}: radius_m must be a positive number in metres, got {value!r}"
        ) from None
    if not (math.isfinite(r) and r > 0):
        raise ValueError(f"{where}: radius_m must be finite and > 0 (metres), got {value!r}")
    return r


def make_trace(time, displacement, force, radius, metadata=None, name: str = "") -> Trace:
    """Build a validated :class:`Trace` from arrays (same checks as the file reader)."""
    label = name or "trace"
    arrays = []
    for col, values in zip(COLUMNS, (time, displacement, force), strict=True):
        a = np.asarray(values, dtype=np.float64)
        if a.ndim != 1:
            raise ValueError(f"{label}: column {col!r} must be 1-D, got shape {a.shape}")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise ValueError(
                f"{label}: row {bad[0]}, column {col!r}: value {a[bad[0]]} is not finite"
            )
        arrays.append(a)
    t, d, f = arrays
    if not (t.size == d.size == f.size):
        raise ValueError(f"{label}: columns have different lengths {t.size}, {d.size}, {f.size}")
    if t.size < MIN_ROWS:
        raise ValueError(f"{label}: need at least {MIN_ROWS} data rows, got {t.size}")
    step = np.flatnonzero(np.diff(t) <= 0)
    if step.size:
        k = step[0] + 1
        raise ValueError(
            f"{label}: row {k}, column 'time_s': time {float(t[k])!r} does not increase "
            f"(previous {float(t[k - 1])!r})"
        )
    meta = dict(metadata or {})
    r = _positive_radius(radius, label)
    meta.setdefault("radius_m", repr(r))
    return Trace(t, d, f, r, meta, name)


def parse_trace(text: str, name: str = "<string>") -> Trace:
    """Parse the CSV text of a trace (see module docstring). Errors name ``name:line:column``."""
    metadata: dict[str, str] = {}
    meta_line: dict[str, int] = {}
    header: list[str] | None = None
    header_line = 0
    rows: list[list[float]] = []
    row_lines: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            if header is not None:
                raise ValueError(
                    f"{name}: line {lineno}: '# key: value' lines must come before the header row"
                )
            body = line[1:].strip()
            if ":" in body:
                key, value = body.split(":", 1)
                key = key.strip()
                if not key:
                    raise ValueError(f"{name}: line {lineno}: empty metadata key in {raw!r}")
                metadata[key] = value.strip()
                meta_line[key] = lineno
            continue  # a plain comment
        cells = [c.strip() for c in line.split(",")]
        if header is None:
            header, header_line = cells, lineno
            seen = set()
            for j, col in enumerate(cells, start=1):
                if col not in COLUMNS:
                    raise ValueError(
                        f"{name}: line {lineno}, column {j}: unknown column {col!r} "
                        f"(expected {', '.join(COLUMNS)})"
                    )
                if col in seen:
                    raise ValueError(f"{name}: line {lineno}, column {j}: duplicate column {col!r}")
                seen.add(col)
            missing = [c for c in COLUMNS if c not in seen]
            if missing:
                raise ValueError(
                    f"{name}: line {lineno}: missing column(s) {', '.join(missing)} "
                    f"(header is {line!r})"
                )
            continue
        if len(cells) != len(header):
            raise ValueError(
                f"{name}: line {lineno}: expected {len(header)} cells ({', '.join(header)}), "
                f"got {len(cells)}"
            )
        values = []
        for j, (col, cell) in enumerate(zip(header, cells, strict=True), start=1):
            try:
                v = float(cell)
            except ValueError:
                raise ValueError(
                    f"{name}: line {lineno}, column {j} ({col}): {cell!r} is not a number"
                ) from None
            if not math.isfinite(v):
                raise ValueError(
                    f"{name}: line {lineno}, column {j} ({col}): {cell!r} is not finite"
                )
            values.append(v)
        rows.append(values)
        row_lines.append(lineno)
    if header is None:
        raise ValueError(f"{name}: no header row (expected {','.join(COLUMNS)})")
    if "radius_m" not in metadata:
        raise ValueError(
            f"{name}: missing '# radius_m: <metres>' header line (the sphere radius R is required)"
        )
    radius = _positive_radius(metadata["radius_m"], f"{name}: line {meta_line['radius_m']}")
    if len(rows) < MIN_ROWS:
        raise ValueError(
            f"{name}: need at least {MIN_ROWS} data rows after the header (line {header_line}), "
            f"got {len(rows)}"
        )
    data = np.asarray(rows, dtype=np.float64)
    cols = {c: data[:, header.index(c)] for c in COLUMNS}
    t = cols["time_s"]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = bad[0] + 1
        j = header.index("time_s") + 1
        raise ValueError(
            f"{name}: line {row_lines[k]}, column {j} (time_s): time {float(t[k])!r} is not "
            f"greater than the previous row's {float(t[k - 1])!r} (must increase)"
        )
    return Trace(t, cols["displacement_m"], cols["force_N"], radius, metadata, name)


def read_trace(path) -> Trace:
    """Read a trace CSV file (see module docstring for the format)."""
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read trace file ({exc.strerror or exc})") from None
    return parse_trace(text, name=path)


def format_trace(trace: Trace) -> str:
    """The CSV text of a trace: metadata lines, header, rows (round-trips through parse_trace)."""
    lines = []
    meta = dict(trace.metadata)
    meta.setdefault("radius_m", repr(float(trace.radius)))
    for key, value in meta.items():
        if "\n" in str(value) or ":" in key or not key.strip():
            raise ValueError(f"metadata key/value not representable on one line: {key!r}")
        lines.append(f"# {key}: {value}")
    lines.append(",".join(COLUMNS))
    for t, d, f in zip(trace.time, trace.displacement, trace.force, strict=True):
        lines.append(f"{t:.6g},{d:.7e},{f:.6e}")
    return "\n".join(lines) + "\n"


def write_trace(path, trace: Trace) -> None:
    """Write a trace as CSV (creates parent folders)."""
    path = os.fspath(path)
    folder = os.path.dirname(path)
    if folder:
        os.makedirs(folder, exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(format_trace(trace))

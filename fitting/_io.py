"""Reading and writing force traces (the format of ``data/README.md``).

The project's own file is plain UTF-8 text (a leading byte-order mark is accepted)::

    # radius_m: 2.0e-3          <- required: sphere (or reduced, eq 24) radius R [m]
    # poisson_ratio: 0.5        <- optional; any other "# key: value" line is kept as metadata
    # drive: force              <- optional: travel (default), spring, force (load control)
    # stiffness_N_m: 5000       <- optional: the load cell's stiffness (then drive spring)
    # units: force=mN           <- optional: units of the columns (converted to SI)
    time_s,displacement_m,force_N
    0.0,0.0,0.0012
    ...

* ``time_s`` strictly increasing [s];
* ``displacement_m`` indenter travel d(t) toward the substrate since the first row [m]
  (positive = toward it; the gap is z(t) = z0 - d(t), z0 unknown);
* ``force_N`` normal force [N], positive when the film/substrate pushes back.

Instrument exports are read as they are: the separator is found from the rows of numbers
(';' or tabs where most rows have them, else ',', else whitespace; decimal commas where the
separator is not ','), lines without '#' before the header row (a vendor's block) are skipped,
and ``columns=`` maps cells by header name or number (other cells ignored; no header row needed
with numbers). A column's unit is, first found: ``units=``, the ``# units:`` line, the unit in
its header cell (``force_mN``, ``Load (uN)``, ``Load [uN]``), else SI; ``force_sign=-1`` flips
the force. The trace is SI from then on (``metadata["read_as"]`` says what was converted).

Every malformed input raises :class:`TraceError` (a ``ValueError``) naming the file, the line
(1-based) and, for cell errors, the column. Scales the thin-film model cannot describe (travel
beyond ``MAX_SPHERE_TRAVEL_OVER_RADIUS`` R, |force| above ``MAX_FORCE_N``, R outside
``RADIUS_RANGE_M``) are refused the same way, with the likely unit mistake
(:func:`check_scales`); a fit with the default paraboloid refuses travel beyond
``MAX_TRAVEL_OVER_RADIUS`` R (naming ``--indenter sphere``), and so is a force negative in
compression refused (:func:`check_force_sign`, once the drive is known).

Reading is numpy-fast: the numeric block goes through ``numpy.loadtxt``; only a file that it
rejects is parsed again line by line, to name the offending line and column. A zip archive
holding one file (a zipped export) is read as that file; one holding several is refused with
their names.
"""

from __future__ import annotations

import codecs
import contextlib
import itertools
import math
import os
import re
import tempfile
import warnings
import zipfile
from array import array
from typing import NamedTuple

import numpy as np

from lubjax._files import write_text
from lubjax._fitting_api import checks as _checks

MAX_TRAVEL_OVER_RADIUS = _checks.MAX_TRAVEL_OVER_RADIUS
MAX_SPHERE_TRAVEL_OVER_RADIUS = _checks.MAX_SPHERE_TRAVEL_OVER_RADIUS

COLUMNS = ("time_s", "displacement_m", "force_N")
MIN_ROWS = 10
#: Larger files are refused (a 200 MB trace reads in a few seconds; decimate anything bigger).
MAX_FILE_BYTES = 1 << 30
#: Sphere radii outside this range [m] are refused (a radius in mm reads as metres: R > 1 m).
RADIUS_RANGE_M = (1e-7, 1.0)
#: |force| above this [N] is refused: far beyond a soft lubricated contact (a wrong unit).
MAX_FORCE_N = 1e3

_EOL = re.compile(r"\r\n|\r|\n")
#: Added to a message about a ','-separated file whose rows split into more cells than expected.
_COMMA_HINT = ("; decimal commas? With ',' as the separator a decimal comma splits a number in "
               "two cells: export with ';' (or tabs) as the separator, or with decimal points")


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
        """A metadata value as a float.

        Args:
            key: the metadata key (``radius_m``, ``speed_m_s``, ...).
            default: what to return when the key is absent or its value is not a number
                (default None).

        Returns:
            The value as a float, or ``default``.
        """
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
    """A header's Poisson ratio (a string) in the solver's range (lubjax.POISSON_RANGE)."""
    try:
        return _checks.check_poisson("poisson_ratio", float(value))
    except (TypeError, ValueError):
        lo, hi = _checks.POISSON_RANGE
        raise TraceError(
            f"{where}: poisson_ratio must be a number in ({lo:g}, {hi:g}], got {value!r}"
        ) from None


#: The drives a fit knows: the values of the ``# drive:`` header key and of ``--drive``.
DRIVES = ("travel", "spring", "force")


def _check_model_keys(metadata: dict, where) -> None:
    """``drive`` one of DRIVES and ``stiffness_N_m`` a positive number; ``where(key)``
    names the place (file and line)."""
    if "drive" in metadata and metadata["drive"] not in DRIVES:
        raise TraceError(
            f"{where('drive')}: drive must be one of {', '.join(DRIVES)} (force: load "
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


def check_scales(trace: Trace, indenter: str = "paraboloid") -> None:
    """TraceError unless the trace's scales fit the thin-film model (see module docstring).

    The model needs travel d ≪ R (and gap z0 ≪ R): a trace whose |displacement| exceeds
    ``MAX_TRAVEL_OVER_RADIUS`` R is refused for the paraboloid (the message names the fix,
    ``--indenter sphere``), more than ``MAX_SPHERE_TRAVEL_OVER_RADIUS`` R for the sphere, as is
    |force| > ``MAX_FORCE_N``. Both catch a column in the wrong unit (mm or μm for m, mN for N)
    that would otherwise fit to nonsense. The readers check for the sphere, the widest limit;
    a fit checks again for its own indenter (``fitting._model.trace_data``).
    """
    name = trace.name or "trace"
    r = float(trace.radius)
    travel = float(np.max(np.abs(trace.displacement))) if trace.displacement.size else 0.0
    limit = _checks.max_travel_over_radius(indenter)
    if travel > MAX_SPHERE_TRAVEL_OVER_RADIUS * r:
        raise TraceError(
            f"{name}: column displacement_m: the travel reaches {travel:.4g} m, "
            f"{travel / r:.3g} times the radius R = {r:g} m; the thin-film model needs travel "
            f"≪ R and refuses more than {limit:g} R. Is displacement_m in "
            "millimetres or micrometres instead of metres? Declare it: --units displacement=um "
            "(or a '# units: displacement=um' line)"
        )
    problem = _checks.travel_over_radius_problem(f"{name}: the travel", travel, r, indenter,
                                                 "radius_m")
    if problem:
        raise TraceError(problem)
    peak = float(np.max(np.abs(trace.force))) if trace.force.size else 0.0
    if peak > MAX_FORCE_N:
        raise TraceError(
            f"{name}: column force_N: |force| reaches {peak:.4g} N, above {MAX_FORCE_N:g} N, "
            "far beyond a soft lubricated contact. Is force_N in another unit (mN, μN)? "
            "Declare it: --units force=mN (or a '# units: force=mN' line)"
        )


#: A force falling as the travel rises this strongly over the loading (Pearson correlation) is
#: a force recorded negative in compression: a film or a solid only pushes back.
NEGATIVE_CORRELATION = -0.5


def check_force_sign(trace: Trace, drive: str = "travel") -> None:
    """TraceError if the force is negative in compression (an instrument's sign convention).

    Position control (``travel``, ``spring``): refused when, over the loading (travel from 5 %
    to 95 % of its final value, up to where it first reaches 95 %), the force falls as the
    travel rises (correlation below ``NEGATIVE_CORRELATION``) and the force's largest excursion
    from its value at rest is negative. Load control (``force``): refused when the final load is
    negative. Either is caught here, before any fitting; the fix is ``--force-sign -1``."""
    name = trace.name or "trace"
    f, d = trace.force, trace.displacement
    n = f.size
    tail = max(3, n // 20)
    fix = ("flip it with --force-sign -1 (force_sign=-1 in read_trace), or record the force "
           "positive when the sphere is pushed back")
    if drive == "force":
        load = float(np.median(f[-tail:]))
        if load < 0 and load < -0.5 * float(np.max(np.abs(f))):
            raise TraceError(
                f"{name}: column force_N: the load the instrument holds is {load:.4g} N, "
                f"negative: the force is negative in compression; {fix}"
            )
        return
    d_end = float(np.median(d[-tail:]))
    if not d_end > 0:
        return  # no travel toward the substrate: scales_from_trace names that
    reached = np.flatnonzero(d >= 0.95 * d_end)
    stop = int(reached[0]) + 1 if reached.size else n
    load = np.flatnonzero(d[:stop] > 0.05 * d_end)
    rest = f[: max(int(load[0]) if load.size else 0, 1)]
    excursion = f - float(np.median(rest))
    if load.size < 5 or np.ptp(f[load]) == 0 or np.ptp(d[load]) == 0:
        corr = -1.0 if excursion.min() < -excursion.max() else 1.0
    else:
        corr = float(np.corrcoef(d[load], f[load])[0, 1])
    if corr < NEGATIVE_CORRELATION and excursion.min() < -excursion.max():
        raise TraceError(
            f"{name}: column force_N: the force falls as the travel rises (correlation "
            f"{corr:.2f} over the loading) and swings to {float(excursion.min()):.4g} N from rest: "
            f"the force is negative in compression; {fix}"
        )


def make_trace(time, displacement, force, radius, metadata=None, name: str = "") -> Trace:
    """A validated :class:`Trace` from arrays (the file reader's checks).

    Args:
        time: sample times t_k [s], 1-D, finite, strictly increasing, at least ``MIN_ROWS``.
        displacement: the indenter's travel d(t_k) toward the substrate [m], as many.
        force: the normal force F(t_k) [N], positive in compression, as many.
        radius: R, the sphere (or reduced) radius [m], > 0.
        metadata: ``# key: value`` metadata (values as strings or numbers); None: none.
        name: where the trace came from (a label; default "").

    Returns:
        Trace: the trace (``radius_m`` added to its metadata).

    Raises:
        TraceError: a column not numeric, not 1-D, not finite, of another length or with a
            time that does not increase (the message names row and column), too few rows, a
            radius not > 0, a Poisson's ratio out of range, or implausible scales.
    """
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
    check_scales(trace, "sphere")
    return trace


# --------------------------------------------------------------------------- units and columns

#: Units a column may be read in (``--units``, a ``# units:`` line, a unit in its header cell),
#: with their factors to SI. "µ" and "μ" are read as "u".
UNITS = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6},
    "displacement": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9},
    "force": {"N": 1.0, "mN": 1e-3, "uN": 1e-6, "nN": 1e-9},
}
QUANTITIES = tuple(UNITS)  # in the order of COLUMNS
_MICRO = str.maketrans({"\u00b5": "u", "\u03bc": "u"})
_SEPARATOR_NAMES = {",": "','", ";": "';'", "\t": "tabs", None: "whitespace"}
#: A split point of "key=value,key=value" lists: a comma before the next "word=".
_PAIR_SPLIT = re.compile(r",(?=\s*[A-Za-z_][\w ]*=)")
#: A line that may be a row of numbers (digits, signs, exponents, separators, decimal marks).
_NUMERIC_LOOK = re.compile(r"^[\d\s.,;eE+\-]*\d[\d\s.,;eE+\-]*$")
#: The header-row search ends after this many such lines in a row (the numeric block has begun).
_NUMERIC_RUN = 5
#: A unit at the end of a header cell: "Load (uN)", "Load [uN]", "force_uN".
_HEADER_UNIT = re.compile(r"^(.*?)\s*(?:\(\s*([^()]*?)\s*\)|\[\s*([^\[\]]*?)\s*\])$")


def _allowed_units(q: str) -> str:
    return ", ".join(UNITS[q])


def _unit(q: str, text: str, where: str) -> str:
    u = text.strip().translate(_MICRO)
    if u not in UNITS[q]:
        raise TraceError(
            f"{where}: unknown unit {text.strip()!r} for the {q} column (allowed: "
            f"{_allowed_units(q)})"
        )
    return u


def _pairs(spec, where: str) -> list[tuple[str, str]]:
    """``"key=value,key=value"`` (or a dict) as (key, value) pairs, keys checked."""
    items = list(spec.items()) if isinstance(spec, dict) else [
        tuple(p.split("=", 1)) if "=" in p else (p, None) for p in _PAIR_SPLIT.split(str(spec))]
    out, seen = [], set()
    for key, value in items:
        key = str(key).strip()
        if value is None or not str(value).strip():
            raise TraceError(f"{where}: {key!r} has no value: write {where.lstrip('-#: ')} as "
                             "time=...,displacement=...,force=...")
        if key not in UNITS:
            raise TraceError(f"{where}: unknown column {key!r} (allowed: {', '.join(QUANTITIES)})")
        if key in seen:
            raise TraceError(f"{where}: column {key!r} is given twice")
        seen.add(key)
        out.append((key, str(value).strip()))
    if not out:
        raise TraceError(f"{where}: empty (give e.g. force=mN,time=ms)")
    return out


def parse_units(spec, where: str = "units") -> dict:
    """Declared units, ``"force=mN,time=ms"`` or a dict, as {column: unit}. Columns: time
    (s, ms, us), displacement (m, mm, um, nm), force (N, mN, uN, nN); TraceError naming the
    column and the allowed units otherwise."""
    return {q: _unit(q, u, f"{where}: {q}") for q, u in _pairs(spec, where)}


def parse_columns(spec, where: str = "columns") -> dict:
    """Which cells hold time, displacement and force: ``"time=Time (s),displacement=2,..."`` as
    {column: header name (str) or 0-based cell index (int)}; a number in the string counts from
    1. A dict is taken as it is: ints are cell indices from 0, strings header names."""
    out = {}
    for q, value in _pairs(spec, where):
        if isinstance(spec, dict) and isinstance(spec[q], int) and not isinstance(spec[q], bool):
            if spec[q] < 0:
                raise TraceError(f"{where}: {q}={spec[q]}: cell indices start at 0")
            out[q] = spec[q]
            continue
        text = _unquote(value)
        if text.isdigit() and not isinstance(spec, dict):
            if int(text) < 1:
                raise TraceError(f"{where}: {q}={text}: columns are numbered from 1")
            out[q] = int(text) - 1
        else:
            out[q] = text
    missing = [q for q in QUANTITIES if q not in out]
    if missing:
        raise TraceError(f"{where}: missing {', '.join(missing)} (give all three: "
                         "time=...,displacement=...,force=..., by header name or number)")
    numbers = [v for v in out.values() if isinstance(v, int)]
    if len(set(numbers)) < len(numbers):
        raise TraceError(f"{where}: two quantities map to the same column number")
    return out


def _unquote(cell: str) -> str:
    cell = cell.strip()
    if len(cell) >= 2 and cell[0] == cell[-1] and cell[0] in "\"'":
        cell = cell[1:-1].strip()
    return cell


def _canonical(cell: str):
    """(quantity, unit) of a header cell named like the project's columns (``time_s``,
    ``force_mN``, ``displacement_um``), else None."""
    q, _, u = _unquote(cell).partition("_")
    if q in UNITS and u.translate(_MICRO) in UNITS[q]:
        return q, u.translate(_MICRO)
    return None


def _cell_unit(cell: str):
    """The unit written at the end of a header cell ("Load (uN)", "Load [uN]"), or None."""
    canon = _canonical(cell)
    if canon is not None:
        return canon[1]
    m = _HEADER_UNIT.match(_unquote(cell))
    if m is None:
        return None
    return m.group(2) if m.group(2) is not None else m.group(3)


def _split(line: str, sep) -> list[str]:
    return line.split(sep) if sep is not None else line.split()


def _number(cell: str, comma: bool) -> float:
    return float(cell.replace(",", ".") if comma else cell)


def _is_numeric(cells, comma, idx=None) -> bool:
    """All cells numbers (or those at ``idx`` that the row has), and at least two."""
    if idx is not None:
        idx = [j for j in idx if j < len(cells)]
        if len(idx) < 2:
            return False
    try:
        for j in range(len(cells)) if idx is None else idx:
            _number(cells[j], comma)
    except (ValueError, IndexError):
        return False
    return len(cells) >= 2


class _Layout(NamedTuple):
    """Where a file's numbers are and how to read them."""

    metadata: dict
    radius: float
    sep: str | None  # ',', ';', '\t' or None (whitespace)
    comma: bool  # decimal commas
    use: tuple  # 0-based cell of time, displacement, force
    labels: tuple  # how messages name those columns
    ncells: int  # cells per row: exactly (the project's own format) or at least
    exact: bool
    scale: tuple  # factor to SI per column (the force's sign included)
    header_line: int  # 0: no header row

    def cells_text(self) -> str:
        sep = _SEPARATOR_NAMES[self.sep]
        what = f"{self.ncells} cells" if self.exact else f"at least {self.ncells} cells"
        if self.exact:
            what += f" ({', '.join(self.labels)})"
        return f"{what} separated by {sep}"


def _metadata(lines, name: str) -> tuple[dict, dict]:
    """The ``# key: value`` lines: {key: value} and {key: line}; duplicate keys refused."""
    metadata: dict[str, str] = {}
    meta_line: dict[str, int] = {}
    for lineno, line in lines:
        if not line.startswith("#"):
            continue
        body = line[1:].strip()
        if ":" not in body:
            continue  # a plain comment
        key, value = body.split(":", 1)
        key = key.strip()
        if not key:
            raise TraceError(f"{name}: line {lineno}: empty metadata key in {line!r}")
        if key in metadata:
            raise TraceError(
                f"{name}: lines {meta_line[key]} and {lineno} both give '# {key}:' "
                f"({metadata[key]!r}, {value.strip()!r}); keep one"
            )
        metadata[key] = value.strip()
        meta_line[key] = lineno
    return metadata, meta_line


def _detect_separator(body) -> tuple:
    """(separator, decimal commas) from the lines that look like rows of numbers: ';' or tabs
    when most of them have one, else ',' when most do, else whitespace. Decimal commas only
    where the separator is not ','."""
    sample = [line for _, line in body if _NUMERIC_LOOK.match(line)][:20]
    if not sample:
        sample = [line for _, line in body][-_NUMERIC_RUN:]
    sep = next((s for s in (";", "\t", ",") if 2 * sum(s in x for x in sample) > len(sample)),
               None)
    return sep, sep != "," and any("," in x for x in sample)


def _header_cells(line: str, sep, n: int | None) -> list[str]:
    """A header row's cells; with whitespace separators, names with single spaces in them
    ("Load (uN)") are kept whole when the cells are 2+ spaces or tabs apart."""
    cells = [_unquote(c) for c in _split(line, sep)]
    if sep is None and n is not None and len(cells) != n:
        wide = [_unquote(c) for c in re.split(r"\t|\s{2,}", line.strip())]
        if len(wide) == n:
            return wide
    return cells


def _preamble(lines, name: str) -> list:
    """The ``(lineno, stripped text)`` lines up to and including the first run of
    ``_NUMERIC_RUN`` numeric-looking rows (where the data have surely begun)."""
    buf = []
    run = 0
    for lineno, raw in lines:
        if "\x00" in raw:
            raise TraceError(
                f"{name}: line {lineno}: NUL byte: a binary file (or UTF-16 text), not a UTF-8 CSV"
            )
        line = raw.strip()
        buf.append((lineno, line))
        if line and not line.startswith("#"):
            run = run + 1 if _NUMERIC_LOOK.match(line) else 0
            if run >= _NUMERIC_RUN:
                break
    return buf


def _uneven(sep, body) -> bool:
    """Whether the numeric-looking rows of a ','-separated ``body`` differ in their number of
    cells (as decimal commas make them: "0,5,12,1" next to "1,13,2")."""
    counts = {len(_split(line, sep)) for _, (_, line) in body if _NUMERIC_LOOK.match(line)}
    return sep == "," and len(counts) > 1


def _header_index(body, first, sep, n_data, columns, by_number, idx, name: str, hint: str):
    """Index into ``body`` of the header row (None: a file without one, read by column number);
    ``first``: index of the first data row; ``hint``: added to a message (decimal commas)."""
    expected = ",".join(COLUMNS)

    def no_header():
        return TraceError(
            f"{name}: no header row (expected {expected}; a file without one needs --columns by "
            f"number, e.g. --columns time=1,displacement=2,force=3{hint})"
        )

    h = None
    if columns is None:
        h = next((i for i, (_, (_, line)) in enumerate(body[:first])
                  if any(_canonical(c) for c in _split(line, sep))), None)
        if h is None:
            if first is None and body:
                h = 0
            elif first:
                h = first - 1
            else:
                raise no_header()
    elif by_number:
        if first is None:
            raise TraceError(
                f"{name}: no rows of numbers in columns "
                f"{', '.join(str(j + 1) for j in idx)} (separated by {_SEPARATOR_NAMES[sep]})"
            )
        # the line before the data is their header row only if it has as many cells (not the
        # last line of a vendor's block)
        h = first - 1 if first and len(_header_cells(body[first - 1][1][1], sep, n_data)) == (
            n_data) else None
    else:
        names = [v for v in columns.values() if isinstance(v, str)]
        h = next((i for i, (_, (_, line)) in enumerate(body)
                  if all(x in _header_cells(line, sep, n_data) for x in names)), None)
        if h is None:
            cand = first - 1 if first else (0 if first is None and body else None)
            if cand is None:
                raise TraceError(
                    f"{name}: no header row: give --columns by number (e.g. "
                    "--columns time=1,displacement=2,force=3)"
                )
            n, line = body[cand][1]
            cells = _header_cells(line, sep, n_data)
            missing = next(x for x in names if x not in cells)
            raise TraceError(
                f"{name}: line {n}: column {missing!r} not found; the header has: "
                f"{', '.join(repr(c) for c in cells)} (separated by {_SEPARATOR_NAMES[sep]})"
            )
    return h


def _column_scales(metadata, meta_line, labels, header_units, head_line, units, force_sign,
                   name: str) -> list:
    """Each column's factor to SI (and the force's sign): a ``--units`` option over a
    ``# units:`` line over a unit in the header cell, else SI. Notes what was converted in
    ``metadata["read_as"]``."""
    declared = {}
    if "units" in metadata:
        declared = parse_units(metadata.pop("units"), f"{name}: line {meta_line['units']}: units")
    declared.update(units or {})
    scale, read_as = [], []
    for q, label, hu in zip(QUANTITIES, labels, header_units, strict=True):
        if q in declared:
            u = declared[q]
        elif hu is not None:
            u = _unit(q, hu, f"{name}: line {head_line}: column {label!r}")
        else:
            u = next(iter(UNITS[q]))
        scale.append(UNITS[q][u])
        if scale[-1] != 1.0:
            read_as.append(f"{q} in {u}")
    if force_sign == -1:
        scale[2] = -scale[2]
        read_as.append("force sign flipped")
    if read_as:
        metadata["read_as"] = ", ".join(read_as)
    return scale


def _scan(lines, name: str, columns=None, units=None, force_sign=1.0):
    """Read ``(lineno, text)`` pairs until the numeric block has begun; find the separator, the
    header row (vendor lines before it skipped), the metadata and each column's cell and unit.

    Returns (layout, pending): ``pending`` are the lines read after the header row (or, without
    one, from the first data row), still to be parsed as data."""
    buf = _preamble(lines, name)
    if not any(line for _, line in buf):
        what = "holds only blank lines" if buf else "is empty"
        raise TraceError(f"{name}: the file {what}: no header row, no data")
    body = [(k, (n, line)) for k, (n, line) in enumerate(buf) if line and not line.startswith("#")]
    sep, comma = _detect_separator([x for _, x in body])
    by_number = columns is not None and all(isinstance(v, int) for v in columns.values())
    idx = sorted(columns.values()) if by_number else None
    first = next((i for i, (_, (_, line)) in enumerate(body)
                  if _is_numeric(_split(line, sep), comma, idx)), None)
    n_data = len(_split(body[first][1][1], sep)) if first is not None else None
    hint = _COMMA_HINT if _uneven(sep, body) else ""
    h = _header_index(body, first, sep, n_data, columns, by_number, idx, name, hint)
    if h is not None:
        k_head, (head_line, head_text) = body[h]
        start = k_head + 1
    else:
        k_head, head_line, head_text = None, 0, None
        start = body[first][0]
    meta_end = k_head if k_head is not None else start
    metadata, meta_line = _metadata(buf[:meta_end], name)
    cells = _header_cells(head_text, sep, n_data) if head_text is not None else None
    if columns is None:
        use, labels, header_units = _canonical_columns(cells, head_line, head_text, name, sep,
                                                       hint)
        ncells, exact = len(cells), True
    else:
        use, labels, header_units = _mapped_columns(columns, cells, head_line, name)
        ncells, exact = max(use) + 1, False
        if n_data is not None and n_data < ncells:
            j = max(use)
            raise TraceError(
                f"{name}: line {body[first][1][0]}: column {j + 1} ({labels[use.index(j)]}) is "
                f"not there: the rows have {n_data} cells separated by {_SEPARATOR_NAMES[sep]}"
            )
    if "radius_m" not in metadata:
        raise TraceError(
            f"{name}: missing '# radius_m: <metres>' header line (the sphere radius R is required)"
        )
    radius = _positive_radius(metadata["radius_m"], f"{name}: line {meta_line['radius_m']}")
    if "poisson_ratio" in metadata:
        _poisson(metadata["poisson_ratio"], f"{name}: line {meta_line['poisson_ratio']}")
    _check_model_keys(metadata, lambda key: f"{name}: line {meta_line[key]}")
    scale = _column_scales(metadata, meta_line, labels, header_units, head_line, units,
                           force_sign, name)
    layout = _Layout(metadata, radius, sep, comma, tuple(use), tuple(labels), ncells, exact,
                     tuple(scale), head_line)
    return layout, buf[start:]


def _canonical_columns(cells, line: int, text: str, name: str, sep, hint: str = ""):
    """The project's own header: time_s, displacement_m, force_N (a unit suffix may differ:
    force_mN), in any order, nothing else; ``hint`` is added to the unknown column's message."""
    found = {}
    for j, col in enumerate(cells, start=1):
        canon = _canonical(col)
        if canon is None:
            sep_hint = "" if sep == "," else f"; the file is separated by {_SEPARATOR_NAMES[sep]}"
            raise TraceError(
                f"{name}: line {line}, column {j}: unknown column {col!r} (expected "
                f"{', '.join(COLUMNS)}{sep_hint}; to read other columns or ignore extra ones, give "
                f"--columns time=...,displacement=...,force=...{hint})"
            )
        if canon[0] in found:
            raise TraceError(f"{name}: line {line}, column {j}: duplicate column {col!r}")
        found[canon[0]] = (j - 1, col, canon[1])
    missing = [c for c, q in zip(COLUMNS, QUANTITIES, strict=True) if q not in found]
    if missing:
        raise TraceError(
            f"{name}: line {line}: missing column(s) {', '.join(missing)} (header is {text!r})"
        )
    return ([found[q][0] for q in QUANTITIES], [found[q][1] for q in QUANTITIES],
            [found[q][2] for q in QUANTITIES])


def _mapped_columns(columns: dict, cells, line: int, name: str):
    """Cells, labels and header units of a ``columns`` mapping (names looked up in ``cells``)."""
    use, labels, header_units = [], [], []
    for q in QUANTITIES:
        v = columns[q]
        if isinstance(v, str):
            hits = [j for j, c in enumerate(cells) if c == v]
            if len(hits) > 1:
                raise TraceError(
                    f"{name}: line {line}: column {v!r} appears {len(hits)} times in the header "
                    f"(columns {', '.join(str(j + 1) for j in hits)}): give {q} by number"
                )
            j = hits[0]
        else:
            j = v
        if j in use:
            raise TraceError(f"{name}: columns: {QUANTITIES[use.index(j)]} and {q} are both "
                             f"column {j + 1}")
        use.append(j)
        if cells is not None and j < len(cells):
            labels.append(cells[j])
            header_units.append(_cell_unit(cells[j]))
        else:
            labels.append(f"{q}, column {j + 1}")
            header_units.append(None)
    return use, labels, header_units


def _finish(name: str, lay: _Layout, data: np.ndarray) -> Trace:
    """SI arrays from the parsed columns (time, displacement, force), checked for scale."""
    cols = [np.ascontiguousarray(data[:, k]) * s if s != 1.0 else np.ascontiguousarray(data[:, k])
            for k, s in enumerate(lay.scale)]
    trace = Trace(*cols, lay.radius, lay.metadata, name)
    check_scales(trace, "sphere")
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


def _options(columns, units, force_sign) -> dict:
    if force_sign not in (1, -1):
        raise TraceError(f"force_sign must be 1 or -1, got {force_sign!r}")
    return dict(columns=None if columns is None else parse_columns(columns),
                units=None if units is None else parse_units(units), force_sign=force_sign)


def parse_trace(text: str, name: str = "<string>", *, columns=None, units=None,
                force_sign: int = 1) -> Trace:
    """Parse the text of a trace (the format: :mod:`fitting._io`'s module docstring).

    Args:
        text: the file's text: ``# key: value`` metadata lines, a header and rows.
        name: where the text came from, named in errors as ``name:line:column`` (default
            "<string>").
        columns: None (the header names the columns: time_s, displacement_m, force_N), or which
            cells hold them, ``"time=Time (s),displacement=2,force=Load (uN)"`` or a dict (header
            names, or cell numbers from 1 in the string, from 0 in a dict): other cells are
            ignored, and a unit in brackets in the header cell is the column's unit.
        units: units of the columns, ``"force=mN,time=ms"`` or a dict (over a ``# units:`` line
            and the header's); converted to SI on reading.
        force_sign: 1 (default) or -1, which flips the force (an instrument that records
            compression as negative).

    Returns:
        Trace: the trace, in SI units (s, m, N).

    Raises:
        TraceError: malformed text (the message names ``name:line:column``), a ``columns``,
            ``units`` or ``force_sign`` it cannot use, or the checks of :func:`make_trace`.
    """
    opts = _options(columns, units, force_sign)
    if text.startswith("\ufeff"):
        text = text[1:]
    lines = _iter_lines(text)
    lay, pending = _scan(lines, name, **opts)
    order = sorted(range(3), key=lambda k: lay.use[k])  # cells read left to right
    values = array("d")
    row_lines = array("q")
    widths = set()  # the rows' numbers of cells
    for lineno, raw in itertools.chain(pending, lines):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            raise TraceError(
                f"{name}: line {lineno}: '# key: value' lines must come before the header row"
            )
        cells = _split(line, lay.sep)
        widths.add(len(cells))
        if len(cells) != lay.ncells if lay.exact else len(cells) < lay.ncells:
            hint = _COMMA_HINT if lay.sep == "," and len(cells) > lay.ncells else ""
            raise TraceError(
                f"{name}: line {lineno}: expected {lay.cells_text()}, got {len(cells)}{hint}"
            )
        row = [0.0, 0.0, 0.0]
        for k in order:
            j = lay.use[k]
            cell = cells[j]
            try:
                v = _number(cell, lay.comma)
            except ValueError:
                raise TraceError(
                    f"{name}: line {lineno}, column {j + 1} ({lay.labels[k]}): {cell.strip()!r} "
                    "is not a number"
                ) from None
            if not math.isfinite(v):
                raise TraceError(
                    f"{name}: line {lineno}, column {j + 1} ({lay.labels[k]}): {cell.strip()!r} "
                    "is not finite"
                )
            row[k] = v
        values.extend(row)
        row_lines.append(lineno)
    if len(row_lines) < MIN_ROWS:
        after = f" after the header (line {lay.header_line})" if lay.header_line else ""
        raise TraceError(
            f"{name}: need at least {MIN_ROWS} data rows{after}, got {len(row_lines)}"
        )
    data = np.frombuffer(values, dtype=np.float64).reshape(-1, 3)
    t = data[:, 0]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = bad[0] + 1
        hint = _COMMA_HINT if lay.sep == "," and len(widths) > 1 else ""
        raise TraceError(
            f"{name}: line {row_lines[k]}, column {lay.use[0] + 1} ({lay.labels[0]}): time "
            f"{float(t[k])!r} is not greater than the previous row's {float(t[k - 1])!r} "
            f"(must increase){hint}"
        )
    return _finish(name, lay, data)


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


def _check_size(size: int, name: str) -> None:
    if size > MAX_FILE_BYTES:
        raise TraceError(
            f"{name}: the file is {size / 1e9:.3g} GB; traces over "
            f"{MAX_FILE_BYTES / 1e9:.3g} GB are refused (decimate it)"
        )


def _zip_error(path, exc) -> TraceError:
    return TraceError(f"{path}: a zip archive that cannot be read ({exc}): unzip it and give "
                      "the file inside")


#: JPK's file types, zip archives themselves (fitting._afm reads them).
JPK_EXTENSIONS = (".jpk-force", ".jpk-force-map", ".jpk-qi-data", ".jpk-qi-series")
#: What a zip archive can raise on reading: corrupt, truncated, encrypted, an unknown method.
_ZIP_ERRORS = (zipfile.BadZipFile, EOFError, RuntimeError, NotImplementedError)


def zip_export(path) -> str | None:
    """The one file inside a zip archive (a zipped export): its name in the archive.

    Args:
        path: any file.

    Returns:
        None when ``path`` is not a zip archive, else the name of the only file in it (folders
        and what macOS adds, ``__MACOSX/`` and ``.DS_Store``, do not count).

    Raises:
        TraceError: an archive that holds no file or several (they are named: unzip it and
            give the one to read), or that cannot be read.
    """
    try:
        if not zipfile.is_zipfile(path):
            return None
        with zipfile.ZipFile(path) as z:
            names = [i.filename for i in z.infolist() if not i.is_dir()
                     and not i.filename.startswith("__MACOSX/")
                     and os.path.basename(i.filename) != ".DS_Store"]
    except _ZIP_ERRORS as exc:
        raise _zip_error(path, exc) from None
    if os.fspath(path).lower().endswith(JPK_EXTENSIONS):  # JPK's own files are zip archives
        raise TraceError(f"{path}: a JPK AFM file, not a trace file: read it with "
                         "fitting.read_afm (lubjax-fit reads it as it is)")
    if len(names) == 1:
        return names[0]
    if not names:
        raise TraceError(f"{path}: a zip archive with no file in it")
    shown = ", ".join(names[:4]) + (f", ... ({len(names)} files)" if len(names) > 4 else "")
    raise TraceError(f"{path}: a zip archive holding {len(names)} files ({shown}): unzip it "
                     "and give the file(s) to read")


def zip_head(path, member: str, size: int = 4096) -> bytes:
    """The first ``size`` bytes of ``member`` in the zip archive ``path`` (b"" if unreadable)."""
    try:
        with zipfile.ZipFile(path) as z, z.open(member) as fh:
            return fh.read(size)
    except (OSError, *_ZIP_ERRORS):
        return b""


@contextlib.contextmanager
def unzipped(path):
    """``(file, name)`` of a file to read: ``path`` itself, or for a zip archive holding one
    file (:func:`zip_export`) that file, extracted into a temporary folder removed on exit,
    and named ``path/member`` (in messages, and as a trace's name)."""
    member = zip_export(path)
    if member is None:
        yield path, os.fspath(path)
        return
    with tempfile.TemporaryDirectory(prefix="lubjax-unzip-") as tmp:
        try:
            with zipfile.ZipFile(path) as z:
                _check_size(z.getinfo(member).file_size, os.path.join(path, member))
                file = z.extract(member, tmp)
        except _ZIP_ERRORS as exc:
            raise _zip_error(path, exc) from None
        yield file, os.path.join(path, member)


def _read_fast(path: str, opts: dict) -> Trace | None:
    """The header block line by line, the numeric block by ``numpy.loadtxt``; None if the block
    (or an encoding error) needs the line-by-line parser to name what is wrong."""
    with open(path, encoding="utf-8-sig", newline=None) as fh:
        lines = ((n, s.rstrip("\n")) for n, s in enumerate(iter(fh.readline, ""), start=1))
        try:
            lay, pending = _scan(lines, path, **opts)
        except UnicodeDecodeError:
            return None
        rows = itertools.chain((line for _, line in pending), fh)
        if lay.comma:  # the separator is not ',': every ',' is a decimal mark
            rows = (line.replace(",", ".") for line in rows)
        cols = None if lay.exact else sorted(set(lay.use))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "input contained no data"
                data = np.loadtxt(rows, delimiter=lay.sep, comments=None, ndmin=2,
                                  dtype=np.float64, usecols=cols)
        except ValueError:  # UnicodeDecodeError included
            return None
    width = lay.ncells if lay.exact else len(cols)
    if data.shape[1] != width or data.shape[0] < MIN_ROWS:
        return None
    pick = lay.use if lay.exact else [cols.index(j) for j in lay.use]
    data = data[:, pick]
    if not (np.isfinite(data).all() and np.all(np.diff(data[:, 0]) > 0)):
        return None
    return _finish(path, lay, data)


def read_trace(path, *, columns=None, units=None, force_sign: int = 1) -> Trace:
    """Read a trace file (see the module docstring of :mod:`fitting._io` for the format).

    Args:
        path: the file (CSV with ``# key: value`` metadata lines, a header and rows).
        columns: which cells hold time, displacement and force, as :func:`parse_trace`.
        units: units of the columns, as :func:`parse_trace` (converted to SI on reading).
        force_sign: -1 flips the force, as :func:`parse_trace`.

    Returns:
        Trace: the trace, in SI units (s, m, N).

    Raises:
        TraceError: a folder, a file over ``MAX_FILE_BYTES``, a file that cannot be read, a zip
            archive that does not hold exactly one file (one that does is read as that file),
            or malformed contents (the message names the file, line and column); a ValueError.

    Example:
        ```python
        import fitting

        trace = fitting.read_trace("data/paper_dc140.csv")
        assert trace.time.size == trace.force.size and trace.radius > 0
        ```
    """
    path = os.fspath(path)
    opts = _options(columns, units, force_sign)
    try:
        if os.path.isdir(path):
            raise TraceError(f"{path}: is a folder, not a trace file")
        _check_size(os.path.getsize(path), path)
        member = zip_export(path)
        if member is not None:  # a zipped export: read as the file inside
            with unzipped(path) as (file, name):
                with open(file, "rb") as fh:
                    raw = fh.read()
            return parse_trace(_decode(raw, name), name=name, **opts)
        trace = _read_fast(path, opts)
        if trace is None:  # something is wrong or unusual: the careful parser names it
            with open(path, "rb") as fh:
                raw = fh.read()
            trace = parse_trace(_decode(raw, path), name=path, **opts)
    except OSError as exc:
        raise TraceError(f"{path}: cannot read trace file ({exc.strerror or exc})") from None
    return trace


def format_trace(trace: Trace) -> str:
    """The CSV text of a trace: metadata lines, header, rows (round-trips through
    :func:`parse_trace`).

    Args:
        trace: the :class:`Trace`.

    Returns:
        str: ``# key: value`` lines, the header ``time_s,displacement_m,force_N`` and one
        row per sample.

    Raises:
        TraceError: a metadata key or value that cannot be written on one line.
    """
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
    """Write a trace as CSV (:func:`format_trace`), atomically, creating parent folders.

    Args:
        path: the file to write.
        trace: the :class:`Trace`.

    Raises:
        TraceError: as :func:`format_trace`.
        OSError: the file cannot be written.
    """
    write_text(path, format_trace(trace))

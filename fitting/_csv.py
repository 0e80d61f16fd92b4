"""Reading and writing force traces as delimited text (the format of ``data/README.md``).

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

Instrument exports are read as they are: the separator, the decimal mark, the header row after
a vendor's block, the columns and their units are found as :mod:`fitting._columns` says
(``columns=``, ``units=``, ``force_sign=``). The trace is SI from then on
(``metadata["read_as"]`` says what was converted).

Every malformed input raises :class:`fitting._trace.TraceError` naming the file, the line
(1-based) and, for cell errors, the column; a trace read passes the checks of
:mod:`fitting._trace` (its scales, its radius, its metadata).

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
import tempfile
import warnings
import zipfile
from array import array

import numpy as np

from lubjax._fitting_api import files as _files

from ._columns import (
    COMMA_HINT,
    EOL,
    FileLayout,
    number,
    parse_columns,
    parse_units,
    scan,
    split_cells,
)
from ._trace import COLUMNS, MIN_ROWS, Trace, TraceError, check_scales

#: Larger files are refused (a 200 MB trace reads in a few seconds; decimate anything bigger).
MAX_FILE_BYTES = 1 << 30


def _finish(name: str, lay: FileLayout, data: np.ndarray) -> Trace:
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
        m = EOL.search(text, pos)
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
    """Parse the text of a trace (the format: :mod:`fitting._csv`'s module docstring).

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
    lay, pending = scan(lines, name, **opts)
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
        cells = split_cells(line, lay.sep)
        widths.add(len(cells))
        if len(cells) != lay.ncells if lay.exact else len(cells) < lay.ncells:
            hint = COMMA_HINT if lay.sep == "," and len(cells) > lay.ncells else ""
            raise TraceError(
                f"{name}: line {lineno}: expected {lay.cells_text()}, got {len(cells)}{hint}"
            )
        row = [0.0, 0.0, 0.0]
        for k in order:
            j = lay.use[k]
            cell = cells[j]
            try:
                v = number(cell, lay.comma)
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
        hint = COMMA_HINT if lay.sep == "," and len(widths) > 1 else ""
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
        line = len(EOL.findall(data[: exc.start].decode("utf-8", "replace"))) + 1
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
            lay, pending = scan(lines, path, **opts)
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
    """Read a trace file (see the module docstring of :mod:`fitting._csv` for the format).

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
    _files.write_text(path, format_trace(trace))

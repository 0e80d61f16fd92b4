"""Where a delimited export keeps its trace: separator, decimal mark, header row, columns, units.

The separator is found from the rows of numbers (';' or tabs where most rows have them, else
',', else whitespace; decimal commas where the separator is not ','); lines without '#' before
the header row (a vendor's block) are skipped; ``columns=`` maps cells by header name or number
(other cells ignored; no header row needed with numbers). A column's unit is, first found:
``units=``, the ``# units:`` line, the unit in its header cell (``force_mN``, ``Load (uN)``,
``Load [uN]``), else SI; ``force_sign=-1`` flips the force (:func:`scan`, the file's
:class:`FileLayout`). Every malformed input raises :class:`fitting._trace.TraceError` naming the
file, the line (1-based) and, for cell errors, the column.
"""

from __future__ import annotations

import re
from typing import NamedTuple

from ._trace import (
    COLUMNS,
    TraceError,
    check_model_keys,
    poisson_ratio,
    positive_radius,
)

EOL = re.compile(r"\r\n|\r|\n")
#: Added to a message about a ','-separated file whose rows split into more cells than expected.
COMMA_HINT = ("; decimal commas? With ',' as the separator a decimal comma splits a number in "
              "two cells: export with ';' (or tabs) as the separator, or with decimal points")


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


def split_cells(line: str, sep) -> list[str]:
    return line.split(sep) if sep is not None else line.split()


def number(cell: str, comma: bool) -> float:
    return float(cell.replace(",", ".") if comma else cell)


def _is_numeric(cells, comma, idx=None) -> bool:
    """All cells numbers (or those at ``idx`` that the row has), and at least two."""
    if idx is not None:
        idx = [j for j in idx if j < len(cells)]
        if len(idx) < 2:
            return False
    try:
        for j in range(len(cells)) if idx is None else idx:
            number(cells[j], comma)
    except (ValueError, IndexError):
        return False
    return len(cells) >= 2


class FileLayout(NamedTuple):
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
    cells = [_unquote(c) for c in split_cells(line, sep)]
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
    counts = {len(split_cells(line, sep)) for _, (_, line) in body if _NUMERIC_LOOK.match(line)}
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
                  if any(_canonical(c) for c in split_cells(line, sep))), None)
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


def scan(lines, name: str, columns=None, units=None, force_sign=1.0):
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
                  if _is_numeric(split_cells(line, sep), comma, idx)), None)
    n_data = len(split_cells(body[first][1][1], sep)) if first is not None else None
    hint = COMMA_HINT if _uneven(sep, body) else ""
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
    radius = positive_radius(metadata["radius_m"], f"{name}: line {meta_line['radius_m']}")
    if "poisson_ratio" in metadata:
        poisson_ratio(metadata["poisson_ratio"], f"{name}: line {meta_line['poisson_ratio']}")
    check_model_keys(metadata, lambda key: f"{name}: line {meta_line[key]}")
    scale = _column_scales(metadata, meta_line, labels, header_units, head_line, units,
                           force_sign, name)
    layout = FileLayout(metadata, radius, sep, comma, tuple(use), tuple(labels), ncells, exact,
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

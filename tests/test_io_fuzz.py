"""Fuzz the trace reader (issue 9): 400 seeded random mutations of data/paper_dc140.csv.

Each mutated file must either load into a valid trace or raise ``fitting._trace.TraceError`` (a
ValueError) whose one-line message starts with the file name and, where it names a line, names
one that exists. Nothing else: no UnicodeDecodeError, IndexError, numpy error, ... And the
numpy fast path of ``read_trace`` must agree with the line-by-line ``parse_trace``: the same
arrays, or the same message.
"""

from __future__ import annotations

import codecs
import re

import numpy as np
import pytest

from fitting._csv import parse_trace, read_trace
from fitting._trace import MIN_ROWS, TraceError

from helpers import SEED_TRACE as SEED_FILE

N_CASES = 400
SEED = open(SEED_FILE, "rb").read()
_EOL = re.compile(rb"\r\n|\r|\n")
_KIND = re.compile(r"0x[0-9a-f]+|-?\d[\d.]*(e[-+]?\d+)?|'[^']*'")  # numbers, quoted cells


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True)


def _first_data_line(lines) -> int:
    return next(i for i, line in enumerate(lines) if line.startswith(b"time_s")) + 1


def m_byte_flip(rng, data):
    b = bytearray(data)
    for _ in range(rng.integers(1, 6)):
        k = rng.integers(len(b))
        b[k] ^= int(rng.integers(1, 256))
    return bytes(b)


def m_random_bytes(rng, data):
    k = rng.integers(len(data))
    junk = rng.integers(0, 256, rng.integers(1, 40)).astype(np.uint8).tobytes()
    return data[:k] + junk + data[k:]


def m_delete_lines(rng, data):
    lines = _lines(data)
    for _ in range(rng.integers(1, 4)):
        del lines[rng.integers(len(lines))]
    return b"".join(lines)


def m_duplicate_line(rng, data):
    lines = _lines(data)
    k = rng.integers(len(lines))
    lines.insert(k, lines[k])
    return b"".join(lines)


def m_truncate_file(rng, data):
    return data[: rng.integers(len(data))]


def m_truncate_line(rng, data):
    lines = _lines(data)
    k = rng.integers(len(lines))
    lines[k] = lines[k][: rng.integers(len(lines[k]))] + b"\n"
    return b"".join(lines)


def m_swap_columns(rng, data):
    lines = _lines(data)
    i, j = rng.choice(3, 2, replace=False)
    start = _first_data_line(lines) - 1
    which = rng.integers(3)  # 0: header only, 1: one row, 2: every row and the header
    for n, line in enumerate(lines):
        if n < start or (which == 0 and n != start) or (which == 1 and n != start + 5):
            continue
        cells = line.rstrip(b"\r\n").split(b",")
        if len(cells) == 3:
            cells[i], cells[j] = cells[j], cells[i]
            lines[n] = b",".join(cells) + b"\n"
    return b"".join(lines)


def m_bad_cell(rng, data):
    lines = _lines(data)
    start = _first_data_line(lines)
    k = rng.integers(start, len(lines))
    cells = lines[k].rstrip(b"\n").split(b",")
    j = rng.integers(len(cells))
    bad = [b"nan", b"NaN", b"inf", b"-inf", b"", b" ", b"1e999", b"1,5", b"0x1p3", b'"1.0"',
           b"1.2.3", b"--1", b"1e", b"\xc2\xa01.0", b"\xef\xbb\xbf1"]  # fmt: skip
    cells[j] = bad[rng.integers(len(bad))]
    lines[k] = b",".join(cells) + b"\n"
    return b"".join(lines)


def m_bom(rng, data):
    return codecs.BOM_UTF8 + data


def m_encoding(rng, data):
    text = data.decode("utf-8").replace("# radius_m", "# probe: 5 µm, 20 °C\n# radius_m", 1)
    enc = ["latin-1", "cp1252", "utf-16", "utf-16-le", "utf-32", "utf-8"][rng.integers(6)]
    return text.encode(enc)


def m_header_garbage(rng, data):
    lines = _lines(data)
    choice = rng.integers(8)
    if choice == 0:  # header row replaced by random printable text
        k = _first_data_line(lines) - 1
        lines[k] = bytes(rng.integers(32, 127, rng.integers(1, 40)).astype(np.uint8)) + b"\n"
    elif choice == 1:  # a duplicated metadata key
        lines.insert(rng.integers(0, 3), b"# radius_m: 3e-3\n")
    elif choice == 2:  # radius value garbage
        lines = [
            b"# radius_m: " + [b"big", b"-1", b"0", b"nan", b"2", b"2e-9", b""][rng.integers(7)]
            + b"\n" if line.startswith(b"# radius_m") else line
            for line in lines
        ]  # fmt: skip
    elif choice == 3:  # Poisson's ratio out of range or not a number
        lines.insert(0, b"# poisson_ratio: " + [b"0.9", b"half", b"-1", b"0.5"][rng.integers(4)]
                     + b"\n")  # fmt: skip
    elif choice == 4:  # metadata after the header
        lines.insert(rng.integers(_first_data_line(lines), len(lines)), b"# late: 1\n")
    elif choice == 5:  # an extra or unknown column name
        k = _first_data_line(lines) - 1
        lines[k] = lines[k].rstrip(b"\n") + [b",temp_C", b",time_s", b","][rng.integers(3)] + b"\n"
    elif choice == 6:  # empty key, comment lines, colon-less comment
        lines.insert(rng.integers(0, 3), [b"#: 1\n", b"# just a note\n", b"#\n"][rng.integers(3)])
    else:  # drop every metadata line
        lines = [line for line in lines if not line.startswith(b"#")]
    return b"".join(lines)


def m_line_endings(rng, data):
    return data.replace(b"\n", [b"\r\n", b"\r", b"\n\n", b"\n \n"][rng.integers(4)])


def m_scale(rng, data):
    """A column in the wrong unit (×1e3, ×1e6, ×1e300) or a sign flip."""
    lines = _lines(data)
    start = _first_data_line(lines)
    j = rng.integers(3)
    factor = [1e3, 1e6, 1e300, -1.0][rng.integers(4)]
    for n in range(start, len(lines)):
        cells = lines[n].rstrip(b"\n").split(b",")
        cells[j] = repr(float(cells[j]) * factor).encode()
        lines[n] = b",".join(cells) + b"\n"
    return b"".join(lines)


def m_time_order(rng, data):
    lines = _lines(data)
    start = _first_data_line(lines)
    k = rng.integers(start, len(lines) - 1)
    lines[k], lines[k + 1] = lines[k + 1], lines[k]
    return b"".join(lines)


def m_nul(rng, data):
    k = rng.integers(len(data))
    return data[:k] + b"\x00" + data[k:]


MUTATIONS = [
    m_byte_flip, m_random_bytes, m_delete_lines, m_duplicate_line, m_truncate_file,
    m_truncate_line, m_swap_columns, m_bad_cell, m_bom, m_encoding, m_header_garbage,
    m_line_endings, m_scale, m_time_order, m_nul,
]  # fmt: skip


def _mutate(case: int) -> tuple[bytes, str]:
    rng = np.random.default_rng(9000 + case)
    data, names = SEED, []
    for _ in range(1 + int(rng.random() < 0.3) + int(rng.random() < 0.1)):
        m = MUTATIONS[rng.integers(len(MUTATIONS))]
        try:
            data = m(rng, data)
        except (StopIteration, ValueError, IndexError):
            continue  # this mutation needs a part an earlier one destroyed
        names.append(m.__name__)
    return data, "+".join(names) or "none"


def _check_valid(tr):
    assert tr.time.ndim == 1 and tr.time.size >= MIN_ROWS
    assert tr.time.size == tr.displacement.size == tr.force.size
    for a in (tr.time, tr.displacement, tr.force):
        assert np.all(np.isfinite(a))
    assert np.all(np.diff(tr.time) > 0)
    assert 0 < tr.radius <= 1.0


def _check_error(exc: TraceError, path: str, data: bytes):
    msg = str(exc)
    assert msg.startswith(f"{path}: "), msg
    assert "\n" not in msg, msg
    n_lines = len(_EOL.findall(data)) + 1
    for n in re.findall(r"\blines? (\d+)(?: and (\d+))?", msg):
        for k in n:
            if k:
                assert 1 <= int(k) <= n_lines, (msg, n_lines)


def test_mutations_load_or_raise_trace_error(tmp_path):
    outcomes = {"loaded": 0, "error": 0}
    kinds = set()
    for case in range(N_CASES):
        data, how = _mutate(case)
        path = str(tmp_path / f"case{case:03d}.csv")
        with open(path, "wb") as fh:
            fh.write(data)
        try:
            fast = read_trace(path)
        except TraceError as exc:
            fast = exc
        except Exception as exc:  # pragma: no cover - the failure this test exists for
            pytest.fail(f"case {case} ({how}): {type(exc).__name__}: {exc}")
        # The line-by-line parser on the decoded text must agree with the fast path.
        try:
            text = data.decode("utf-8")  # parse_trace drops a leading BOM itself
        except UnicodeDecodeError:
            text = None
        if text is None:
            assert isinstance(fast, TraceError), (case, how)
        else:
            try:
                slow = parse_trace(text, name=path)
            except TraceError as exc:
                slow = exc
            except Exception as exc:  # pragma: no cover
                pytest.fail(f"case {case} ({how}) parse_trace: {type(exc).__name__}: {exc}")
            if isinstance(fast, TraceError) or isinstance(slow, TraceError):
                assert str(fast) == str(slow), (case, how)
            else:
                for a, b in zip(fast[:3], slow[:3]):
                    np.testing.assert_array_equal(a, b)
                assert fast.metadata == slow.metadata and fast.radius == slow.radius
        if isinstance(fast, TraceError):
            _check_error(fast, path, data)
            outcomes["error"] += 1
            kinds.add(_KIND.sub("#", str(fast)[len(path) :]))
        else:
            _check_valid(fast)
            assert fast.name == path
            outcomes["loaded"] += 1
    assert sum(outcomes.values()) == N_CASES
    # The fuzz must exercise both outcomes and many different errors.
    assert outcomes["loaded"] >= 40 and outcomes["error"] >= 150, outcomes
    assert len(kinds) >= 15, kinds

"""The limits the docs quote are the code's constants: each quote is found (once) in its page and
read back as a number, so a changed constant or a reworded page fails here instead of drifting.

Also where the docs send readers: the coverage table data/README.md points to is there."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fitting import _afm, _checks, _csv, _trace
from lubjax import _checks as solver_checks

import helpers

ROOT = Path(helpers.ROOT)

_PREFIX = {"": 1.0, "n": 1e-9, "u": 1e-6, "μ": 1e-6, "m": 1e-3, "k": 1e3, "M": 1e6, "G": 1e9}
_QUANTITY = re.compile(r"(?P<x>[0-9.]+(?:e[+-]?[0-9]+)?)\s*(?P<prefix>[numμkMG]?)"
                       r"(?:Pa s|Pa|m/s|m|N|GiB)?")


def number(text: str) -> float:
    """ "1 kPa" -> 1e3, "1e-4" -> 1e-4, "1 nm/s" -> 1e-9, "1 GiB" -> 2**30."""
    m = _QUANTITY.fullmatch(text.strip())
    assert m, f"not a quantity: {text!r}"
    if text.strip().endswith("GiB"):
        return float(m["x"]) * 2**30
    return float(m["x"]) * _PREFIX[m["prefix"]]


def test_the_quantity_reader():
    assert [number(t) for t in ("1 kPa", "1 GPa", "1e-4", "1e4", "1 nm/s", "1 m/s", "0.2",
                                "1000 N", "1e-7", "1 GiB", "1 Pa", "600")] == [
        1e3, 1e9, 1e-4, 1e4, 1e-9, 1.0, 0.2, 1e3, 1e-7, 2**30, 1.0, 600.0]


_RANGE = r"\[(?P<lo>[^,\]]+), (?P<hi>[^\]]+)\]"

#: (page, the quote as a regex with groups lo/hi or x, the code's value(s)).
QUOTES = [
    # the plausibility flags (fitting/_checks.py), in the trace format page and the module
    ("data/README.md", r"^\| E\\\* \| " + _RANGE, _checks.E_STAR_RANGE_PA),
    ("data/README.md", r"^\| E\\\* \|[^|]*; from (?P<x>[^;]+?) for AFM and indenter vendor files",
     _checks.AFM_E_STAR_RANGE_PA[0]),
    ("data/README.md", r"^\| η \| " + _RANGE + " Pa s", _checks.VISCOSITY_RANGE_PA_S),
    ("data/README.md", r"^\| ramp speed d_c/t_c \| " + _RANGE, _checks.SPEED_RANGE_M_S),
    ("fitting/_checks.py", r"^\* E\* in " + _RANGE, _checks.E_STAR_RANGE_PA),
    ("fitting/_checks.py", r"\(from (?P<x>[^)]+?) for AFM files", _checks.AFM_E_STAR_RANGE_PA[0]),
    ("fitting/_checks.py", r"^\* η in " + _RANGE + " Pa s", _checks.VISCOSITY_RANGE_PA_S),
    ("fitting/_checks.py", r"^\* the ramp speed d_c/t_c in " + _RANGE,
     _checks.SPEED_RANGE_M_S),
    ("docs/guide/afm.md", r"flagged as implausible below (?P<x>[^(]+?) \(cells and tissue\), "
     r"not below the (?P<y>\S+ \S+) of\s+tribometer traces",
     (_checks.AFM_E_STAR_RANGE_PA[0], _checks.E_STAR_RANGE_PA[0])),
    # what a trace file is refused for (fitting/_trace.py, fitting/_csv.py)
    ("data/README.md", r"max \\\|`displacement_m`\\\| > (?P<x>[0-9.]+) R \(a fit",
     _trace.MAX_TRAVEL_OVER_RADIUS),
    ("data/README.md", r"with `--indenter sphere`, (?P<x>[0-9.]+) R\)",
     _trace.MAX_SPHERE_TRAVEL_OVER_RADIUS),
    ("data/README.md", r"max \\\|`force_N`\\\| > (?P<x>[0-9.]+ N) \|", _trace.MAX_FORCE_N),
    ("data/README.md", r"`radius_m` outside " + _RANGE + " m", _trace.RADIUS_RANGE_M),
    ("data/README.md", r"^- a file over (?P<x>[0-9.]+ GiB);", _csv.MAX_FILE_BYTES),
    ("data/README.md", r"fewer than (?P<x>[0-9]+) rows", _trace.MIN_ROWS),
    # AFM files (fitting/_afm.py)
    ("docs/guide/afm.md", r"it refuses more than (?P<x>[0-9.]+) R of\s+stage travel",
     _trace.MAX_TRAVEL_OVER_RADIUS),
    ("docs/guide/afm.md", r"the kept travel reaches (?P<x>[0-9.]+) of that", _afm.CAP),
    ("docs/guide/afm.md", r"`--max-samples` \(default (?P<x>[0-9]+)\)", _afm.MAX_SAMPLES),
    ("docs/guide/afm.md", r"within (?P<x>[0-9.]+) times the height sensor's white noise",
     _afm.STAGE_NOISE_FACTOR),
    # the solver's ranges (lubjax/_checks.py)
    ("docs/guide/cli.md", r"β \(eq 8e\) in " + _RANGE, solver_checks.BETA_RANGE),
    ("docs/guide/cli.md", r"\$\\bar z_0\$ in " + _RANGE, solver_checks.Z0_RANGE),
    ("docs/guide/cli.md", r"t̄ at most (?P<x>\S+) \(in SI mode", solver_checks.T_END_MAX),
    ("docs/guide/simulating.md", r"β must lie in " + _RANGE, solver_checks.BETA_RANGE),
    ("docs/guide/simulating.md", r"\$\\bar z_0\$ in " + _RANGE, solver_checks.Z0_RANGE),
    ("docs/guide/errors.md", r"^\| `beta` \| a finite number in " + _RANGE,
     solver_checks.BETA_RANGE),
    ("docs/guide/errors.md", r"^\| `z0` \| a finite number in " + _RANGE,
     solver_checks.Z0_RANGE),
    ("docs/guide/errors.md", r"^\| `t_end` \| after the history's start, at most (?P<x>\S+) \|",
     solver_checks.T_END_MAX),
]


@pytest.mark.parametrize("page, quote, value", QUOTES,
                         ids=[f"{p}:{i}" for i, (p, _, _) in enumerate(QUOTES)])
def test_a_quoted_limit_is_the_codes(page, quote, value):
    text = (ROOT / page).read_text(encoding="utf-8")
    hits = list(re.finditer(quote, text, re.MULTILINE))
    assert len(hits) == 1, f"{page}: the quote {quote!r} found {len(hits)} times"
    groups = {k: v for k, v in hits[0].groupdict().items() if v is not None}
    quoted = tuple(number(groups[k]) for k in ("lo", "hi", "x", "y") if k in groups)
    expected = tuple(value) if isinstance(value, tuple) else (value,)
    assert quoted == tuple(float(v) for v in expected), (page, hits[0].group(0))


def test_the_coverage_table_is_where_the_trace_format_page_says():
    text = (ROOT / "data/README.md").read_text(encoding="utf-8")
    m = re.search(r"the coverage table is\s+in the documentation's Accuracy and speed page "
                  r"\((?P<page>docs/\S+), \"(?P<heading>[^\"]+)\"\)", text)
    assert m, "data/README.md no longer says where the coverage table is"
    target = (ROOT / m["page"]).read_text(encoding="utf-8")
    section = target.split(f"### {m['heading']}\n", 1)
    assert len(section) == 2, f"{m['page']} has no section {m['heading']!r}"
    assert "| scene | noise | converged | parameter | within 1σ | within 2σ |" in (
        section[1].split("\n## ", 1)[0])

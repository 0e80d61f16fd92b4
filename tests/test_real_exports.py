"""Instrument exports as they are: other separators, decimal commas, vendor header blocks, extra
columns, no header row, declared units and a reversed force sign, all read to the SI arrays of
the project's own file, and each mistake named before any fitting.

Every case is built from data/paper_dc140.csv; nothing here runs a fit."""

from __future__ import annotations

import os

import numpy as np
import pytest

from fitting import _checks, parse_trace, read_trace, scales_from_trace
from fitting._columns import parse_columns, parse_units
from fitting._trace import TraceError, check_force_sign

SEED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data",
                    "paper_dc140.csv")
REF = read_trace(SEED)


def _export(sep=",", comma=False, header=None, scale=(1.0, 1.0, 1.0), extra=False,
            preamble="", meta="# radius_m: 2e-3\n", rows=None):
    """The reference trace written as an export: time, displacement, force times ``scale``
    (``extra``: a temperature column first and a status text column last)."""
    lines = [preamble + meta] if (preamble or meta) else []
    if header is not None:
        lines.append(sep.join(header) + "\n")
    n = REF.time.size if rows is None else rows
    for k in range(n):
        cells = [f"{v * s:.10g}" for v, s in zip(
            (REF.time[k], REF.displacement[k], REF.force[k]), scale)]
        if comma:
            cells = [c.replace(".", ",") for c in cells]
        if extra:
            cells = [f"{21.5 + 0.001 * k:.3f}".replace(".", "," if comma else ".")] + cells + [
                "ok"]
        lines.append(sep.join(cells) + "\n")
    return "".join(lines)


def _same_as_reference(tr, rtol=1e-9):
    np.testing.assert_allclose(tr.time, REF.time, rtol=rtol, atol=1e-15)
    np.testing.assert_allclose(tr.displacement, REF.displacement, rtol=rtol, atol=1e-18)
    np.testing.assert_allclose(tr.force, REF.force, rtol=rtol, atol=1e-15)
    assert tr.radius == REF.radius


def _both_paths(tmp_path, text, **kw):
    """read_trace (numpy fast path) and parse_trace (line by line) agree; returns the trace."""
    p = tmp_path / "export.txt"
    p.write_text(text, encoding="utf-8")
    fast = read_trace(p, **kw)
    slow = parse_trace(text, name=str(p), **kw)
    for a, b in zip(fast[:3], slow[:3]):
        np.testing.assert_array_equal(a, b)
    assert fast.metadata == slow.metadata
    return fast


VENDOR = ("Instrument: Tribo-X 3000\nOperator: A. N. Other\nDate: 2024-05-01 10:22\n"
          "Sample rate: 100 Hz\n\n")


@pytest.mark.parametrize("case", ["semicolon_decimal_comma", "tab", "tab_decimal_comma",
                                  "whitespace_preamble", "extra_columns", "no_header"])
def test_exports_read_to_the_reference_si_arrays(case, tmp_path):
    units = ("Time (s)", "Piezo (nm)", "Load (uN)")
    to_units = (1.0, 1e9, 1e6)
    if case == "semicolon_decimal_comma":
        text = _export(";", comma=True, header=units, scale=to_units)
        kw = dict(columns="time=Time (s),displacement=Piezo (nm),force=Load (uN)")
    elif case == "tab":
        text = _export("\t", header=("time_s", "displacement_m", "force_N"))
        kw = {}
    elif case == "tab_decimal_comma":
        text = _export("\t", comma=True, header=("time_ms", "displacement_um", "force_mN"),
                       scale=(1e3, 1e6, 1e3))
        kw = {}
    elif case == "whitespace_preamble":
        text = _export("   ", header=units, scale=to_units, preamble=VENDOR)
        kw = dict(columns="time=Time (s),displacement=Piezo (nm),force=Load (uN)")
    elif case == "extra_columns":
        text = _export(",", header=("Temp (C)", "t [ms]", "d [um]", "F [mN]", "status"),
                       scale=(1e3, 1e6, 1e3), extra=True)
        kw = dict(columns="time=t [ms],displacement=d [um],force=F [mN]")
    else:
        text = _export(",", scale=(1e3, 1e6, 1e3))
        kw = dict(columns="time=1,displacement=2,force=3", units="time=ms,displacement=um,force=mN")
    tr = _both_paths(tmp_path, text, **kw)
    _same_as_reference(tr)


def test_numbered_columns_skip_extra_cells_and_a_vendor_header(tmp_path):
    text = _export(";", comma=True, header=("T", "t", "d", "F", "s"), extra=True, preamble=VENDOR)
    tr = _both_paths(tmp_path, text, columns="time=2,displacement=3,force=4")
    _same_as_reference(tr)


def test_units_line_in_the_file_and_on_the_command_line(tmp_path):
    mN_ms = _export(",", header=("time_s", "displacement_m", "force_N"), scale=(1e3, 1.0, 1e3),
                    meta="# radius_m: 2e-3\n# units: force=mN,time=ms\n")
    tr = _both_paths(tmp_path, mN_ms)
    _same_as_reference(tr)
    assert "units" not in tr.metadata  # the data are SI now: writing it back must not rescale
    assert tr.metadata["read_as"] == "time in ms, force in mN"
    # the command line's units win over the file's line, which wins over the header's
    mixed = _export(",", header=("time_s", "displacement_m", "force_uN"), scale=(1.0, 1.0, 1e3),
                    meta="# radius_m: 2e-3\n# units: force=nN\n")
    _same_as_reference(_both_paths(tmp_path, mixed, units="force=mN"))
    with_line = _export(",", header=("time_s", "displacement_m", "force_uN"),
                        scale=(1.0, 1.0, 1e3), meta="# radius_m: 2e-3\n# units: force=mN\n")
    _same_as_reference(_both_paths(tmp_path, with_line))


@pytest.mark.parametrize("spec, match", [
    ("force=kN", r"unknown unit 'kN' for the force column \(allowed: N, mN, uN, nN\)"),
    ("pressure=Pa", r"unknown column 'pressure' \(allowed: time, displacement, force\)"),
    ("time=min", r"allowed: s, ms, us"),
    ("displacement", r"'displacement' has no value"),
])
def test_unknown_units_name_the_column_and_the_allowed_units(spec, match):
    with pytest.raises(TraceError, match=match):
        parse_units(spec, "--units")


def test_micro_sign_is_accepted():
    assert parse_units("force=µN,displacement=μm") == {"force": "uN", "displacement": "um"}


def test_units_line_in_the_file_is_checked(tmp_path):
    text = _export(",", header=("time_s", "displacement_m", "force_N"),
                   meta="# radius_m: 2e-3\n# units: force=lbf\n")
    with pytest.raises(TraceError, match=r"line 2: units: force: unknown unit 'lbf'"):
        parse_trace(text, name="x.csv")


def test_unit_in_a_header_cell_is_checked():
    text = _export(",", header=("t (s)", "d (m)", "F (kN)"))
    with pytest.raises(TraceError, match=r"line 2: column 'F \(kN\)': unknown unit 'kN'"):
        parse_trace(text, name="x.csv", columns="time=1,displacement=2,force=3")


def test_column_specs():
    assert parse_columns("time=Time, s,displacement=2,force=Load (uN)") == {
        "time": "Time, s", "displacement": 1, "force": "Load (uN)"}
    with pytest.raises(TraceError, match="missing force"):
        parse_columns("time=1,displacement=2")
    with pytest.raises(TraceError, match="same column number"):
        parse_columns("time=1,displacement=1,force=3")


@pytest.mark.parametrize("text, kw, match", [
    # an export with its own header names and no mapping: the header and the separator named
    (_export(";", comma=True, header=("Time (s)", "Piezo (nm)", "Load (uN)")), {},
     r"line 2, column 1: unknown column 'Time \(s\)' .*the file is separated by ';'.*--columns"),
    # an extra column without a mapping
    (_export(",", header=("time_s", "displacement_m", "force_N", "temp_C")), {},
     r"line 2, column 4: unknown column 'temp_C'.*ignore extra ones, give --columns"),
    # no header row
    (_export(",", header=None), {}, r"no header row .*--columns time=1,displacement=2,force=3"),
    # a mapped name that is not in the header
    (_export(";", header=("Time (s)", "Piezo (nm)", "Load (uN)")),
     dict(columns="time=Time (s),displacement=Piezo (nm),force=Force (uN)"),
     r"line 2: column 'Force \(uN\)' not found; the header has: 'Time \(s\)', 'Piezo \(nm\)', "
     r"'Load \(uN\)' \(separated by ';'\)"),
    # a mapped number beyond the row
    (_export(",", header=None), dict(columns="time=1,displacement=2,force=5"),
     r"line 2: column 5 \(force, column 5\) is not there: the rows have 3 cells"),
])
def test_refusals_name_the_cause(text, kw, match):
    with pytest.raises(TraceError, match=match):
        parse_trace(text, name="x.csv", **kw)


COMMA_HINT = (r"decimal commas\? With ',' as the separator a decimal comma splits a number in "
              r"two cells: export with ';' \(or tabs\) as the separator, or with decimal points")


@pytest.mark.parametrize("header, kw, match", [
    # the project's header: a row splits into more cells than it has
    (("time_s", "displacement_m", "force_N"), {},
     r"line 3: expected 3 cells \(time_s, displacement_m, force_N\) separated by ',', got 4; "),
    # a vendor's header, not mapped: --columns is the advice, with the hint
    (("Time (s)", "Piezo (nm)", "Load (uN)"), {}, r"line 2, column 1: unknown column 'Time \(s\)'"),
    # mapped by number: the cells are read, and the time (split at its comma) does not increase
    (("Time (s)", "Piezo (nm)", "Load (uN)"), dict(columns="time=1,displacement=2,force=3"),
     r"line 4, column 1 \(time, column 1\): time 0.0 is not greater than the previous row's 0.0 "
     r"\(must increase\); "),
    # no header row
    (None, {}, r"no header row .*--columns time=1,displacement=2,force=3; "),
])
def test_decimal_commas_with_a_comma_separator_are_named(header, kw, match):
    text = _export(",", comma=True, header=header)
    with pytest.raises(TraceError, match=f"^x.csv: {match}.*{COMMA_HINT}"):
        parse_trace(text, name="x.csv", **kw)
    # like mistakes with decimal points (a cell missing, a time repeated) get no such hint
    lines = _export(",", header=header).splitlines(keepends=True)
    start = 1 if header is None else 2
    if header == ("time_s", "displacement_m", "force_N"):
        lines[start] = lines[start].rsplit(",", 1)[0] + "\n"
    elif "columns" in kw:
        lines[start + 1] = lines[start]
    with pytest.raises(TraceError) as info:
        parse_trace("".join(lines), name="x.csv", **kw)
    assert "decimal" not in str(info.value)


def test_malformed_value_in_an_export_names_line_and_column(tmp_path):
    text = _export(";", comma=True, header=("Time (s)", "Piezo (nm)", "Load (uN)"),
                   scale=(1.0, 1e9, 1e6))
    lines = text.splitlines(keepends=True)
    cells = lines[20].split(";")
    cells[2] = "n/a\n"
    lines[20] = ";".join(cells)
    p = tmp_path / "bad.csv"
    p.write_text("".join(lines))
    with pytest.raises(TraceError, match=r"bad\.csv: line 21, column 3 \(Load \(uN\)\): 'n/a' is "
                       r"not a number"):
        read_trace(p, columns="time=Time (s),displacement=Piezo (nm),force=Load (uN)")


# --------------------------------------------------------------------------- unit mistakes


def _rescaled(time=1.0, force=1.0):
    return REF._replace(time=REF.time * time, force=REF.force * force, name="x.csv")


def test_negative_force_is_refused_before_fitting_with_the_fix():
    neg = _rescaled(force=-1.0)
    with pytest.raises(TraceError, match=r"x\.csv: column force_N: .*negative in compression.*"
                       r"--force-sign -1"):
        check_force_sign(neg, "travel")
    with pytest.raises(TraceError, match="--force-sign -1"):
        scales_from_trace(neg)  # the fit's first step: before any model run
    check_force_sign(REF, "travel")  # the right sign passes
    check_force_sign(REF, "spring")


def test_force_sign_option_flips_it_back(tmp_path):
    text = _export(",", header=("time_s", "displacement_m", "force_N"), scale=(1.0, 1.0, -1.0))
    tr = _both_paths(tmp_path, text, force_sign=-1)
    _same_as_reference(tr)
    assert tr.metadata["read_as"] == "force sign flipped"
    check_force_sign(tr, "travel")


def test_negative_load_under_load_control_is_refused():
    creep = read_trace(os.path.join(os.path.dirname(SEED), "creep_30mN.csv"))
    check_force_sign(creep, "force")
    with pytest.raises(TraceError, match=r"the load .* is negative.*--force-sign -1"):
        check_force_sign(creep._replace(force=-creep.force), "force")


def _values(E_star=3.92e6, viscosity=100.0):
    return {"E_star": E_star, "viscosity": viscosity, "z0": 1.4e-4, "offset": 0.0}


def test_plausible_fit_has_no_flags():
    assert _checks.plausibility_flags(_values(), speed=1e-4) == []


def test_force_in_mN_read_as_N_is_flagged_with_the_unit_fix():
    # what the fit of paper_dc140 with its force in mN under force_N gives: both 1000x
    flags = _checks.plausibility_flags(_values(1.503e9, 4.975e4), speed=1e-4)
    assert len(flags) == 2
    assert "E* = 1.503 GPa" in flags[0] and "use --units force=mN" in flags[0]
    assert "eta = 4.975e+04 Pa s" in flags[1] and "force=mN" in flags[1]


def test_time_in_ms_read_as_s_is_flagged_with_the_unit_fix():
    # E* unchanged, eta 1000x: the time is in ms
    flags = _checks.plausibility_flags(_values(3.92e6, 1.0e5), speed=1e-7)
    assert len(flags) == 1 and "use --units time=ms" in flags[0]


def test_force_in_uN_and_too_soft_and_slow_ramps_are_flagged():
    flags = _checks.plausibility_flags(_values(3.9e12, 1e8), speed=1e-4)
    assert "force=uN" in flags[0]
    flags = _checks.plausibility_flags(_values(3.9, 1e-1), speed=1e-4)
    assert "E* = 3.9 Pa" in flags[0] and "below" in flags[0]
    flags = _checks.plausibility_flags(_values(), speed=1e-10)
    assert "ramp speed" in flags[0] and "1 nm/s" in flags[0]
    flags = _checks.plausibility_flags(_values(), speed=3.0)
    assert "ramp speed" in flags[0] and "1 m/s" in flags[0]


# --------------------------------------------------------------------------- the command line


def _fake_fits(seen):
    """fit_traces stand-in: records its arguments and returns plausible results."""
    from test_cli_errors import _fake_fit

    def fake(traces, **kwargs):
        seen.append((traces, kwargs))
        return _fake_fit(traces)

    return fake


def _write(tmp_path, trace, name):
    from fitting import write_trace

    p = tmp_path / name
    write_trace(p, trace)
    return str(p)


@pytest.mark.parametrize("time, force, warning", [
    (1.0, 1e3, r"E\* = [\d.]+ GPa is above 1 GPa, the top of soft lubricated contact: is the "
               r"force in mN rather than N\? use --units force=mN"),
    (1e3, 1.0, r"eta = [\d.]+e\+05 Pa s is above 10000 Pa s, the top of lubricating films: is "
               r"the time in ms rather than s\? use --units time=ms"),
])
def test_cli_warns_of_a_unit_slip_before_fitting(time, force, warning, tmp_path, monkeypatch,
                                                 capsys):
    import re

    from fitting import _cli as fcli

    path = _write(tmp_path, _rescaled(time=time, force=force), "slip.csv")
    monkeypatch.setattr(fcli, "fit_traces", _fake_fits([]))
    assert fcli.main([path, "--quiet"]) == 0
    err = capsys.readouterr().err
    assert re.search(r"^lubjax-fit: warning: slip\.csv: before fitting, from the data: "
                     + warning, err, re.M), err
    assert fcli.main([_write(tmp_path, REF, "ok.csv"), "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_cli_units_read_the_slipped_file_as_the_reference(tmp_path, monkeypatch, capsys):
    from fitting import _cli as fcli

    path = _write(tmp_path, _rescaled(time=1e3, force=1e3), "slip.csv")
    seen = []
    monkeypatch.setattr(fcli, "fit_traces", _fake_fits(seen))
    assert fcli.main([path, "--quiet", "--units", "time=ms,force=mN"]) == 0
    assert "warning" not in capsys.readouterr().err
    _same_as_reference(seen[0][0][0], rtol=1e-6)


def test_cli_refuses_negative_force_before_fitting(tmp_path, monkeypatch, capsys):
    from fitting import _cli as fcli

    def no_fit(*args, **kwargs):
        raise AssertionError("fitting started")

    path = _write(tmp_path, _rescaled(force=-1.0), "neg.csv")
    monkeypatch.setattr(fcli, "fit_traces", no_fit)
    assert fcli.main([path, "--quiet", "--out", str(tmp_path / "o" / "f.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("lubjax-fit: error: ")
    assert "negative in compression" in err and "--force-sign -1" in err
    assert not (tmp_path / "o").exists()
    seen = []
    monkeypatch.setattr(fcli, "fit_traces", _fake_fits(seen))
    assert fcli.main([path, "--quiet", "--force-sign", "-1"]) == 0
    np.testing.assert_allclose(seen[0][0][0].force, REF.force, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("argv, message", [
    (["--units", "force=kN"], "--units: force: unknown unit 'kN' for the force column (allowed: "
                              "N, mN, uN, nN)"),
    (["--units", "load=mN"], "--units: unknown column 'load' (allowed: time, displacement, force)"),
    (["--columns", "time=1,force=3"], "--columns: missing displacement"),
    (["--columns", "time=Time (s),displacement=2,force=3"], "column 'Time (s)' not found"),
    (["--force-sign", "2"], "argument --force-sign: invalid choice"),
    (["--fix", "viscosity"], "--fix: write NAME=VALUE"),
    (["--fix", "eta=1e-3"], "--fix: unknown parameter 'eta' for this model (allowed: E_star, "
                            "viscosity, z0, offset)"),
    (["--fix", "viscosity=thin"], "--fix viscosity: 'thin' is not a number"),
    (["--fix", "viscosity=1,viscosity=2"], "--fix: viscosity is given twice"),
])
def test_cli_option_errors_are_one_line_before_fitting(argv, message, capsys, monkeypatch):
    from fitting import _cli as fcli

    monkeypatch.setattr(fcli, "fit_traces", _fake_fits([]))
    assert fcli.main([SEED, "--quiet", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err, err


def test_cli_fix_reaches_the_fit(monkeypatch, capsys):
    from fitting import _cli as fcli

    seen = []
    monkeypatch.setattr(fcli, "fit_traces", _fake_fits(seen))
    assert fcli.main([SEED, "--quiet", "--fix", "viscosity=1e-3", "--fix", "z0=1.4e-4"]) == 0
    assert seen[0][1]["fixed"] == {"viscosity": 1e-3, "z0": 1.4e-4}
    assert fcli.main([SEED, SEED.replace("dc140", "dc126"), "--quiet", "--shared", "E_star",
                      "--fix", "viscosity=100"]) == 0
    assert seen[1][1]["fixed"] == {"viscosity": 100.0} and seen[1][1]["shared"] == ("E_star",)
    assert fcli.main([SEED, SEED.replace("dc140", "dc126"), "--quiet", "--shared", "viscosity",
                      "--fix", "viscosity=100"]) == 2
    assert "also in --shared" in capsys.readouterr().err


# --------------------------------------------------------------------------- fixed parameters


def test_fixed_parameters_leave_the_fitted_vector_in_separate_and_joint_layouts():
    from fitting._model import ModelSpec
    from fitting._problem import make_layout

    spec = ModelSpec()  # E_star, viscosity, z0, offset
    theta0 = np.log(np.array([[3.9e6, 100.0, 1.4e-4, 1.0], [4.1e6, 90.0, 1.5e-4, 1.0]]))
    theta0[:, 3] = [0.01, -0.02]
    lay, x0 = make_layout([[0, 1]], spec, ["a", "b"], theta0, ("E_star",), ("viscosity",))
    assert lay.labels[0] == ["E_star", "z0[a]", "offset[a]", "z0[b]", "offset[b]"]
    for t in (0, 1):  # every trace's θ: the fixed viscosity from base, the rest from x
        theta = lay.base[t] + lay.M[t] @ x0[0]
        assert theta[1] == theta0[t, 1]
        assert theta[2] == theta0[t, 2] and theta[3] == theta0[t, 3]
    assert list(lay.active) == [True, False, True, True]
    lay, x0 = make_layout([[0], [1]], spec, ["a", "b"], theta0, (), ("viscosity", "offset"))
    assert lay.labels == [["E_star", "z0"], ["E_star", "z0"]]


@pytest.mark.parametrize("fixed, shared, match", [
    ({"eta": 1.0}, (), r"fixed: unknown parameter 'eta'"),
    ({"viscosity": -1.0}, (), r"fixed: viscosity must be a finite number > 0"),
    ({"z0": float("nan")}, (), r"fixed: z0 must be a finite number > 0"),
    ({"viscosity": 1.0}, ("viscosity",), r"also shared"),
    ({"E_star": 1e6, "viscosity": 1.0, "z0": 1e-4, "offset": 0.0}, (), r"nothing is left to fit"),
])
def test_fixed_values_are_checked(fixed, shared, match):
    from fitting._model import ModelSpec
    from fitting._start import check_fixed

    with pytest.raises(ValueError, match=match):
        check_fixed(fixed, ModelSpec(), shared)


# --------------------------------------------------------------------------- end to end (~15 s)


@pytest.mark.slow
def test_cli_fit_of_force_in_mN_is_flagged_in_console_json_and_report(tmp_path, capsys):
    """The real fit of paper_dc140 with its force in mN under force_N: it converges to an E*
    1000x the truth, and every output says so with the fix; z0 held at its true value."""
    import json

    from fitting import _cli as fcli

    path = _write(tmp_path, _rescaled(force=1e3), "mN.csv")
    out, report = tmp_path / "fit.json", tmp_path / "fit.txt"
    z0 = float(REF.metadata["true_z0_m"])
    assert fcli.main([path, "--quiet", "--no-cache", "--out", str(out), "--report", str(report),
                      "--fix", f"z0={z0!r}"]) == 0
    console = capsys.readouterr()
    fix = "is the force in mN rather than N? use --units force=mN"
    assert "before fitting, from the data: E* = " in console.err and fix in console.err
    assert "  warning: E* = " in console.out and fix in console.out
    d = json.loads(out.read_text())
    assert d["plausible"] is False and any(fix in f for f in d["flags"])
    assert d["E_star_Pa"] == pytest.approx(1e3 * float(REF.metadata["true_E_star_Pa"]), rel=0.03)
    assert d["fixed"] == ["z0"] and d["z0_m"] == z0 and d["stderr"]["z0_m"] == 0.0
    assert fix in report.read_text().split("[[Flags]]")[1]


@pytest.mark.slow
def test_joint_fit_with_a_fixed_viscosity():
    from fitting import fit_traces

    traces = [REF, read_trace(SEED.replace("dc140", "dc126"))]
    res = fit_traces(traces, shared=("E_star",), fixed={"viscosity": 100.0})
    assert all(r.converged for r in res)
    assert res[0].E_star == res[1].E_star and res[0].shared == ("E_star",)
    for r, tr in zip(res, traces):
        assert r.viscosity == 100.0 and r.stderr["viscosity"] == 0.0 and r.fixed == ("viscosity",)
        assert r.stderr["E_star"] > 0 and r.stderr["z0"] > 0
        assert r.z0 == pytest.approx(float(tr.metadata["true_z0_m"]), rel=0.01)
    assert res[0].E_star == pytest.approx(float(REF.metadata["true_E_star_Pa"]), rel=0.02)


# --------------------------------------------------------------------------- fuzz


FUZZ_SEEDS = {
    "semicolon_decimal_comma_vendor": (
        dict(sep=";", comma=True, header=("Time (s)", "Piezo (nm)", "Load (uN)"),
             scale=(1.0, 1e9, 1e6), preamble=VENDOR),
        dict(columns="time=Time (s),displacement=Piezo (nm),force=Load (uN)")),
    "tab_numbered_extra": (
        dict(sep="\t", comma=True, header=None, scale=(1e3, 1e6, 1e3), extra=True),
        dict(columns="time=2,displacement=3,force=4", units="time=ms,displacement=um,force=mN")),
    "whitespace_vendor": (
        dict(sep="  ", header=("time_s", "displacement_m", "force_N"), preamble=VENDOR), {}),
}


@pytest.mark.parametrize("seed", sorted(FUZZ_SEEDS))
def test_mutated_exports_load_or_raise_trace_error_alike_on_both_paths(seed, tmp_path):
    """tests/test_io_fuzz.py's mutations on exports: a TraceError (the same from the numpy path
    and the line-by-line parser) or the same arrays; never another exception."""
    import test_io_fuzz as fuzz

    export, kw = FUZZ_SEEDS[seed]
    seed_bytes = _export(**export).encode()
    outcomes = {"loaded": 0, "error": 0}
    for case in range(100):
        rng = np.random.default_rng(case)
        data = seed_bytes
        for _ in range(1 + int(rng.random() < 0.3)):
            m = fuzz.MUTATIONS[rng.integers(len(fuzz.MUTATIONS))]
            try:
                data = m(rng, data)
            except (StopIteration, ValueError, IndexError):
                continue  # a mutation that needs the project's own header row
        p = tmp_path / f"case{case}.txt"
        p.write_bytes(data)
        try:
            fast = read_trace(p, **kw)
        except TraceError as exc:
            fast = exc
        try:
            slow = parse_trace(data.decode("utf-8"), name=str(p), **kw)
        except UnicodeDecodeError:
            assert isinstance(fast, TraceError)
            slow = fast
        except TraceError as exc:
            slow = exc
        if isinstance(fast, TraceError) or isinstance(slow, TraceError):
            assert str(fast) == str(slow), case
            assert str(fast).startswith(f"{p}: ") and "\n" not in str(fast)
            outcomes["error"] += 1
        else:
            for a, b in zip(fast[:3], slow[:3]):
                np.testing.assert_array_equal(a, b)
            outcomes["loaded"] += 1
    assert outcomes["loaded"] >= 20 and outcomes["error"] >= 20, outcomes


def test_vendor_line_before_numbered_data_is_not_taken_for_a_header():
    # the block's last line ends in "(mN)": read as a header cell, it would rescale the force
    text = _export(",", header=None, preamble="Instrument: X\nLoad cell range (mN)\n")
    tr = parse_trace(text, name="x.csv", columns="time=1,displacement=2,force=3")
    _same_as_reference(tr)
    with pytest.raises(TraceError, match=r"time and force are both column 1"):
        parse_trace(_export(",", header=("a", "b", "c")), name="x.csv",
                    columns="time=a,displacement=b,force=a")

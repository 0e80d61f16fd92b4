"""Issue 9, case by case: bad input and unsafe outputs in both command lines.

Every failure must be one line on stderr (no traceback) with exit status 2 (bad usage or input,
found before any computation) or 1 (a failed run, an output that could not be written); no
input file and no existing output may be damaged. The CLIs run in-process (``main(argv)``) with
the solver and the fit replaced by stand-ins that fail the test if they are reached, so that
"validated before any computation" is checked, not assumed; a few cases run end to end.
"""

from __future__ import annotations

import dataclasses
import errno
import hashlib
import json
import os
import shutil
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import lubjax
import lubjax._cli as lcli
import lubjax._cli_output as lout
import lubjax._solve as lsolve
from fitting import _cli as fcli
from fitting._csv import parse_trace, read_trace
from fitting._fit import FitResult
from fitting._model import ModelSpec
from fitting._scales import Scales
from fitting._start import Start
from fitting._trace import TraceError
from lubjax import _files
from lubjax._checks import T_END_MAX

from helpers import ROOT
from helpers import SEED_TRACE as SEED

SI = ["--E-star", "3.92e6", "--viscosity", "100", "--radius", "2e-3", "--speed", "1e-4",
      "--indent", "140e-6", "--gap", "140e-6"]  # fmt: skip


def _digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def _one_line_error(err: str, prog: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    assert lines[0].startswith(f"{prog}: error: "), err
    return lines[0]


# --------------------------------------------------------------------------- stand-ins


def _fake_result(t_end=1.0, n=20):
    t = np.linspace(0.0, t_end, n)
    r = np.linspace(0.0, 3.0, 30)
    return SimpleNamespace(
        t=t, force=np.sin(t) + 0.1, film_min=0.5 - 0.1 * t, film_center=0.6 - 0.1 * t,
        run_s=0.01, compile_s=0.02, ok=True, beta=100.0, z0=0.5, r=r,
        profile_times=np.array([0.5, 1.0]), pressure=np.ones((2, 30)), film=np.ones((2, 30)),
        force_error=np.full(n, 1e-4), film_min_error=np.full(n, 1e-5),
        film_center_error=np.full(n, 1e-5), accepted=n - 1, rejected=0,
        unresolved_film=lambda: None, problems=list,
    )  # fmt: skip


def _fake_fit(traces, **kwargs):
    spec = ModelSpec()
    names = spec.names
    out = []
    for tr in traces:
        scales = Scales(1.4e-4, 1e-4, tr.radius, 1.0, 1.4, 1.0, 0.036, 1.4e-4)
        stats = dict(n_samples=tr.time.size, n_parameters=4, dof=tr.time.size - 4, chi2=1.0,
                     reduced_chi2=1.0, autocorrelation_lag1=0.0, durbin_watson=2.0,
                     noise_model="white", n_effective=float(tr.time.size), log_likelihood=0.0,
                     aic=8.0, bic=10.0, rms_residual=1e-4, noise_sigma=1e-4, condition=10.0,
                     max_correlation=0.5, error_parts={})
        values = dict(
            name=tr.name, spec=spec, values=dict(zip(names, (3.9e6, 100.0, 1.4e-4, 0.0))),
            stderr=dict(zip(names, (1e4, 1.0, 1e-6, 1e-5))), correlation=np.eye(4), shared=(),
            group=(), scales=scales, stats=stats, converged=True, identifiable=True,
            n_iterations=3, n_model_runs=7, method="lm", wall_s=0.1,
            start=Start(dict(zip(names, (3e6, 80.0, 1.2e-4, 0.0))), ()), flags=("ok",),
            time=tr.time, data=tr.force, model=tr.force, metadata=tr.metadata,
        )  # fmt: skip
        out.append(FitResult(**{k: values.get(k) for k in FitResult._fields}))
    return out


def _no_compute(*args, **kwargs):
    raise AssertionError("the computation started before the inputs/outputs were checked")


@pytest.fixture
def no_run(monkeypatch):
    """Any solver run or fit fails the test: errors must come before them."""
    monkeypatch.setattr(lsolve, "relax", _no_compute)
    monkeypatch.setattr(fcli, "fit_traces", _no_compute)


@pytest.fixture
def trace(tmp_path):
    p = tmp_path / "trace.csv"
    shutil.copy(SEED, p)
    return p


# --------------------------------------------------------------------------- lubjax relax

DIM = ["relax", "--beta", "100", "--z0", "0.5"]
LAYER = ["--substrate", "layer", "--thickness"]
VISCO = ["--substrate", "viscoelastic"]
PRONY = ["--prony-g", "1", "--prony-tau", "1"]

RELAX_USAGE = [
    # (argv, expected message fragment) -- item 5, 8, 9 of the issue
    (DIM + ["--dr", "0"], "argument --dr: must be a finite number > 0, got '0'"),
    (DIM + ["--rtol", "0"], "argument --rtol: must be a finite number > 0"),
    (DIM + ["--rtol", "0.5"], "Settings.rtol must be in [1e-10, 0.1]"),
    (DIM + ["--max-steps", "3"], "Settings.max_steps must be an integer >= 10"),
    (DIM + ["--dr", "nan"], "argument --dr: must be a finite number > 0"),
    (DIM + ["--dr", "-0.01"], "argument --dr: must be a finite number > 0"),
    (DIM + ["--t-end", "0"], "argument --t-end: must be a finite number > 0"),
    (DIM + ["--t-end", "-1e3"], "argument --t-end: must be a finite number > 0"),
    # beyond the solver's longest run: in the units the user gave (s in SI mode, t_c = 1.4 s)
    (DIM + ["--t-end", "1e12"], "--t-end 1e+12: the solver runs to t̄ = 1e+09 at most (in t_c "
     "units); give at most 1e+09"),
    (["relax"] + SI + ["--t-end", "1e12"], "--t-end 1e+12 s is t̄ = 7.143e+11 (t_c = "
     "--indent/--speed = 1.4 s); the solver runs to t̄ = 1e+09 at most, 1.4e+09 s here: give "
     "--t-end <= 1.4e+09 s"),
    (["relax"] + SI + ["--poisson", "0.6"], "give either --E-star or --E with --poisson"),
    (["relax"] + SI[:1] + ["-3.92e6"] + SI[2:], "E_star must be finite and > 0"),
    (["relax"] + SI[:1] + ["-3.92E+06"] + SI[2:], "E_star must be finite and > 0"),
    (["relax"] + SI[:2] + ["--viscosity", "-1e2"] + SI[4:], "viscosity must be finite and > 0"),
    (["relax"] + SI[:-2] + ["--gap", "nan"], "gap must be finite and > 0"),
    (["relax"] + SI[:-4] + ["--indent", "0.14", "--gap", "140e-6"], "--indent 0.14 m is 70"),
    (["relax"] + SI[:-2] + ["--gap", "1e-2"], "paraboloid indenter models at most 0.2 R"),
    (["relax", "--E", "3e6", "--poisson", "0.6"] + SI[2:], "poisson_ratio must be in (-1, 0.5]"),
    (["relax", "--E", "3e6"] + SI[2:], "SI mode needs --E-star (or --E with --poisson)"),
    (DIM + ["--poisson", "0.3"], "give either --beta/--z0 or SI parameters, not both"),
    (["relax", "--beta", "100"], "give --beta and --z0, or the SI parameters"),
    (DIM + ["--beta", "1e300"], "beta must be finite and in ["),
    (DIM + ["--beta", "1e300", "--out", "{tmp}/new/r.json"], "beta must be finite and in ["),
    (DIM + ["--order", "4"], "argument --order: invalid choice"),
    (["relax", "--beta", "x", "--z0", "1"], "argument --beta: invalid float value: 'x'"),
    (["frobnicate"], "invalid choice: 'frobnicate'"),
    ([], "the following arguments are required: COMMAND"),
    (DIM + ["--out", ""], "--out: empty file name"),
    (DIM + ["--plot", ""], "--plot: empty file name"),
    (DIM + ["--plot", "figplain"], "plot file 'figplain' has no extension"),
    (DIM + ["--plot", "fig.xyz"], "unknown format '.xyz' (use one of .png, .pdf"),
    (DIM + ["--out", "/dev/full"], "exists and is not a regular file"),
    (DIM + ["--out", "{tmp}"], "is a folder; give a file name"),
    (DIM + ["--out", "{tmp}/sub/"], "is a folder; give a file name"),
    (DIM + ["--out", "{tmp}/afile/run.json"], "cannot write in folder"),
    (DIM + ["--out", "{tmp}/r.json", "--plot", "{tmp}/../{name}/r.json"], "unknown format"),
    (DIM + ["--out", "{tmp}/r.pdf", "--plot", "{tmp}/./r.pdf"], "are the same file"),
    # substrate options
    (DIM + ["--thickness", "5e-3"], "--thickness: only with --substrate layer"),
    (["relax"] + SI + ["--layer-base", "frictionless"], "--layer-base: only with --substrate"),
    (DIM + ["--substrate", "layer"], "--substrate layer needs --thickness H (metres)"),
    (DIM + LAYER + ["5e-3"], "--thickness is in metres: give the SI"),
    (["relax"] + SI + LAYER + ["0"], "argument --thickness: must be a finite number > 0"),
    (["relax"] + SI + LAYER + ["5e-3", "--layer-poisson", "0.7"], "--layer-poisson must be in"),
    (["relax"] + SI + LAYER + ["5e-3", "--layer-base", "glued"], "--layer-base: invalid choice"),
    (["relax"] + SI + ["--substrate", "brick"], "argument --substrate: invalid choice"),
    (["relax"] + SI + LAYER + ["1e-6"], "1e-06 m: Layer thickness H̄ = 0.00188982 is too thin"),
    # viscoelastic substrate (issue 10, item 5): Prony options only with it, and all of them
    (DIM + PRONY, "--prony-g, --prony-tau: only with --substrate viscoelastic"),
    (["relax"] + SI + LAYER + ["5e-3", "--prony-tau", "1"],
     "--prony-tau: only with --substrate viscoelastic"),
    (DIM + VISCO, "--substrate viscoelastic needs --prony-g and --prony-tau"),
    (DIM + VISCO + ["--prony-g", "1"], "--substrate viscoelastic needs --prony-tau"),
    (DIM + VISCO + ["--prony-g", "1,0", "--prony-tau", "1,2"],
     "--prony-g: term 2 must be a finite number > 0 (weights E_k/E∞), got 0"),
    (DIM + VISCO + ["--prony-g", "-0.5", "--prony-tau", "1"],
     "--prony-g: term 1 must be a finite number > 0"),
    (DIM + VISCO + ["--prony-g", "nan", "--prony-tau", "1"],
     "--prony-g: term 1 must be a finite number > 0"),
    (DIM + VISCO + ["--prony-g", "1,x", "--prony-tau", "1,2"], "--prony-g: term 2 is not a number"),
    (["relax"] + SI + VISCO + ["--prony-g", "1", "--prony-tau", "0"],
     "--prony-tau: term 1 must be a finite number > 0 (times in s), got 0"),
    (DIM + VISCO + ["--prony-g", "1", "--prony-tau", "-2"],
     "--prony-tau: term 1 must be a finite number > 0 (times in t_c units)"),
    (DIM + VISCO + ["--prony-g", "1,0.5", "--prony-tau", "1"],
     "--prony-g has 2 term(s) and --prony-tau 1: give one relaxation time per weight"),
    (DIM + VISCO + ["--prony-g", "1,0.5", "--prony-tau", "1,1"],
     "--prony-tau: the relaxation times must be distinct"),
    (DIM + VISCO + PRONY + ["--thickness", "5e-3"], "--thickness is in metres: give the SI"),
    (["relax"] + SI + VISCO + PRONY + ["--layer-base", "frictionless"],
     "--layer-base: with --substrate viscoelastic only together with --thickness"),
    (["relax"] + SI + VISCO + PRONY + ["--thickness", "1e-6"], "1e-06 m: Layer thickness H̄"),
    (DIM + ["--thickness", "5e-3", "--prony-g", "1"], "--thickness: only with --substrate layer"),
]


@pytest.mark.parametrize("argv, message", RELAX_USAGE)
def test_relax_usage_errors_are_one_line_exit_2_before_running(
    argv, message, tmp_path, capsys, no_run
):
    (tmp_path / "afile").write_text("x")
    argv = [a.format(tmp=tmp_path, name=tmp_path.name) for a in argv]
    assert lcli.main(argv) == 2
    line = _one_line_error(capsys.readouterr().err, "lubjax")
    assert message in line
    assert sorted(os.listdir(tmp_path)) == ["afile"]  # nothing written, no folder created
    assert (tmp_path / "afile").read_text() == "x"


def test_relax_help_is_plain_text_with_exit_codes(capsys):
    for argv in (["--help"], ["relax", "--help"]):
        assert lcli.main(argv) == 0
        out = capsys.readouterr().out
        assert "``" not in out and ":func:" not in out
        assert "exit status" in out and "2  bad usage or input" in out
        assert "--debug" in out


def test_relax_refused_write_leaves_files_untouched(tmp_path, capsys, no_run):
    old = tmp_path / "run.json"
    old.write_text('{"old": 1}')
    before = _digest(old)
    assert lcli.main(DIM + ["--out", str(old), "--plot", str(tmp_path / "run")]) == 2
    assert "no extension" in _one_line_error(capsys.readouterr().err, "lubjax")
    assert _digest(old) == before and os.listdir(tmp_path) == ["run.json"]


def test_relax_unwritable_folder_is_refused_before_running(tmp_path, capsys, no_run, monkeypatch):
    # As root, chmod does not stop writes, so the folder probe's failure is simulated.
    def read_only(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(_files.tempfile, "mkstemp", read_only)
    assert lcli.main(DIM + ["--out", str(tmp_path / "run.json")]) == 2
    line = _one_line_error(capsys.readouterr().err, "lubjax")
    assert "cannot write in folder" in line and "Permission denied" in line


def test_relax_failed_write_after_run_is_exit_1_and_atomic(tmp_path, capsys, monkeypatch):
    """A disk that fills up during the write: the old JSON stays whole, no temp file is left."""
    monkeypatch.setattr(lsolve, "relax", lambda *a, **k: _fake_result())
    old = tmp_path / "run.json"
    old.write_text('{"old": 1}')

    def dump_then_fail(obj, fh, **kwargs):
        fh.write('{"t": [0.0, 0.1')
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(lout.json, "dump", dump_then_fail)
    assert lcli.main(DIM + ["--out", str(old)]) == 1
    line = _one_line_error(capsys.readouterr().err, "lubjax")
    assert f"cannot write {old}: No space left on device" in line
    assert old.read_text() == '{"old": 1}'
    assert os.listdir(tmp_path) == ["run.json"]


def test_relax_solver_failure_is_exit_1(capsys, monkeypatch):
    def fail(*args, **kwargs):
        raise lsolve.SolverError("contains NaN\nat step 3")

    monkeypatch.setattr(lsolve, "relax", fail)
    assert lcli.main(DIM) == 1
    assert "contains NaN / at step 3" in _one_line_error(capsys.readouterr().err, "lubjax")


def test_relax_internal_error_is_one_line_unless_debug(capsys, monkeypatch):
    def bug(*args, **kwargs):
        raise KeyError("oops")

    monkeypatch.setattr(lsolve, "relax", bug)
    assert lcli.main(DIM) == 1
    line = _one_line_error(capsys.readouterr().err, "lubjax")
    assert "internal error KeyError" in line and "--debug" in line
    with pytest.raises(KeyError):
        lcli.main(DIM + ["--debug"])
    with pytest.raises(KeyError):
        lcli.main(["--debug"] + DIM)


def test_relax_writes_atomically_with_fake_run(tmp_path, monkeypatch, capsys):
    """Outputs replace old files whole, keep their permissions, and --plot follows the extension."""
    monkeypatch.setattr(lsolve, "relax", lambda *a, **k: _fake_result())
    out, plot = tmp_path / "o" / "run.json", tmp_path / "o" / "run.svg"
    assert lcli.main(DIM + ["--out", str(out), "--plot", str(plot)]) == 0
    assert json.loads(out.read_text())["beta"] == 100.0
    assert plot.read_text().lstrip().startswith("<?xml")
    assert sorted(os.listdir(out.parent)) == ["run.json", "run.svg"]
    assert os.stat(out).st_mode & 0o777 == 0o666 & ~_umask()


def _recording_relax(monkeypatch):
    """Replace the solver by a stand-in that records its keyword arguments (returned)."""
    seen = {}

    def fake(*args, **kwargs):
        seen.update(kwargs)
        return _fake_result()

    monkeypatch.setattr(lsolve, "relax", fake)
    return seen


def test_relax_runs_to_the_longest_end_time_it_quotes(monkeypatch, capsys):
    """The limit an SI --t-end is refused with, given back, runs (to t̄ = T_END_MAX)."""
    assert lcli.main(["relax"] + SI + ["--t-end", "1e12"]) == 2
    limit = _one_line_error(capsys.readouterr().err, "lubjax").rsplit("--t-end <= ", 1)[1]
    seen = []
    monkeypatch.setattr(lsolve, "relax", lambda *a, **k: seen.append(a[2]) or _fake_result())
    assert lcli.main(["relax"] + SI + ["--t-end", limit.removesuffix(" s")]) == 0
    assert 0.999 * T_END_MAX <= seen[0] <= T_END_MAX


def test_relax_passes_the_layer_to_the_solver(tmp_path, monkeypatch, capsys):
    """--substrate layer: H in metres becomes H̄ = H/√(R d_c) (9.45 for the paper's sample), the
    layer's ν defaults to --poisson, and the JSON records the substrate."""
    seen = _recording_relax(monkeypatch)
    out = tmp_path / "run.json"
    argv = (["relax", "--E", "2.94e6", "--poisson", "0.45"] + SI[2:]
            + LAYER + ["5e-3", "--layer-base", "frictionless", "--out", str(out)])
    assert lcli.main(argv) == 0
    layer = seen["substrate"]
    assert isinstance(layer, lubjax.Layer) and layer.interface == "frictionless"
    assert layer.thickness == pytest.approx(5e-3 / np.sqrt(2e-3 * 140e-6)) and layer.poisson == 0.45
    assert json.loads(out.read_text())["substrate"]["thickness_bar"] == pytest.approx(9.449, 1e-3)
    assert "frictionless layer H = 0.005 m" in capsys.readouterr().out
    assert lcli.main(DIM) == 0 and seen["substrate"] is None  # the half-space by default


def test_relax_passes_the_viscoelastic_solid_to_the_solver(tmp_path, monkeypatch, capsys):
    """--substrate viscoelastic: the Prony times in s become t_c units (t_c = d_c/v0 = 1.4 s
    here), g_k = E_k/E∞ is from_prony's convention (so Σ g ≥ 1 is fine: E0/E∞ = 1 + Σ g), the
    elastic part is the layer with --thickness, and --beta/--z0 takes the times in t_c units."""
    seen = _recording_relax(monkeypatch)
    out = tmp_path / "run.json"
    argv = ["relax"] + SI + VISCO + ["--prony-g", "2,0.5", "--prony-tau", "0.7,7",
                                     "--out", str(out)]
    assert lcli.main(argv) == 0
    solid = seen["substrate"]
    ref = lubjax.Viscoelastic.from_prony([2.0, 0.5], [0.5, 5.0])
    assert isinstance(solid, lubjax.Viscoelastic) and isinstance(solid.elastic, lubjax.HalfSpace)
    np.testing.assert_allclose(solid.retardation, ref.retardation, rtol=1e-12)
    np.testing.assert_allclose(solid.times, ref.times, rtol=1e-12)
    rec = json.loads(out.read_text())["substrate"]
    assert rec["kind"] == "viscoelastic" and rec["elastic"] == {"kind": "halfspace"}
    assert rec["prony_g"] == [2.0, 0.5] and rec["prony_tau_s"] == [0.7, 7.0]
    assert rec["prony_tau_bar"] == pytest.approx([0.5, 5.0]) and rec["E0_over_Einf"] == 3.5
    assert "relaxed" in rec["modulus"]
    assert "E*0/E*inf = 3.5" in capsys.readouterr().out

    argv = ["relax"] + SI + VISCO + PRONY + LAYER[2:] + ["5e-3", "--out", str(out)]
    assert lcli.main(argv) == 0
    assert seen["substrate"].elastic == lubjax.Layer(5e-3 / np.sqrt(2e-3 * 140e-6), 0.5)
    rec = json.loads(out.read_text())["substrate"]
    assert rec["elastic"]["kind"] == "layer" and rec["elastic"]["thickness_m"] == 5e-3

    assert lcli.main(DIM + VISCO + ["--prony-g", "1", "--prony-tau", "2", "--out", str(out)]) == 0
    np.testing.assert_allclose(seen["substrate"].times, [4.0])  # λ = τ(1 + g), τ in t_c units
    rec = json.loads(out.read_text())["substrate"]
    assert rec["prony_tau_s"] is None and rec["prony_tau_bar"] == [2.0]


@pytest.mark.slow
def test_relax_viscoelastic_peak_force_above_the_relaxed_half_space(tmp_path, capsys):
    """End to end: during the ramp (t_c = 1.4 s, τ = 0.7 s) the solid is stiffer than its relaxed
    modulus (up to E*0 = 2 E*∞), so the peak force exceeds the half-space's at E*∞ = --E-star,
    and stays below the stiffest possible, the half-space at E*0."""
    runs = {}
    for name, extra in [("relaxed", []), ("instant", ["--E-star", "7.84e6"] + SI[2:]),
                        ("visco", VISCO + ["--prony-g", "1", "--prony-tau", "0.7"])]:
        out = tmp_path / f"{name}.json"
        base = SI if name != "instant" else []
        argv = ["relax"] + base + extra + ["--t-end", "2.8", "--rtol", "1e-3", "--dr", "0.1",
                                           "--out", str(out)]
        assert lcli.main(argv) == 0
        runs[name] = json.loads(out.read_text())
    peak = {k: max(v["force_N"]) for k, v in runs.items()}
    assert runs["visco"]["substrate"]["kind"] == "viscoelastic"
    assert runs["visco"]["substrate"]["prony_tau_bar"] == pytest.approx([0.5])
    assert runs["relaxed"]["substrate"] == {"kind": "halfspace"}
    assert 1.1 * peak["relaxed"] < peak["visco"] < peak["instant"]


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


# --------------------------------------------------------------------------- lubjax-fit


FIT_USAGE = [
    # (argv with {trace} = a copy of data/paper_dc140.csv, {tmp}, message fragment)
    (["{trace}", "--out", "{trace}"], "is the input trace"),
    (["{trace}", "--table", "{trace}"], "is the input trace"),
    (["{trace}", "--out", "{tmp}/../{name}/trace.csv"], "is the input trace"),
    (["{trace}", "--out", "{tmp}/link.json"], "is the input trace"),  # symlink to the trace
    (["{trace}", "--table", "{tmp}/hard.csv"], "is the input trace"),  # hard link to it
    (["{trace}", "--out", "{tmp}/f.json", "--table", "{tmp}/f.json"], "are the same file"),
    (["{trace}", "--out", ""], "--out: empty file name"),
    (["{trace}", "--table", " "], "--table: empty file name"),
    (["{trace}", "--plot", "{tmp}/figplain"], "has no extension: name the format"),
    (["{trace}", "{tmp}/hard.csv", "--plot", ""], "is given twice"),
    (["{trace}", SEED, "--plot", "{tmp}/figplain"], "'{tmp}/figplain' has no extension"),
    (["{trace}", SEED, "--plot", " "], "--plot: empty file name"),
    (["{trace}", "--plot", "{tmp}/fig.xyz"], "unknown format '.xyz'"),
    (["{trace}", "--plot", "{tmp}/fig.csv"], "unknown format '.csv'"),
    (["{trace}", "--out", "/dev/full"], "exists and is not a regular file"),
    (["{trace}", "--out", "{tmp}"], "is a folder; give a file name"),
    (["{trace}", "--out", "{trace}/x.json"], "cannot write in folder"),
    (["{trace}", "{trace}"], "is given twice"),
    (["{trace}", "--max-iter", "0"], "argument --max-iter: must be an integer ≥ 1"),
    (["{trace}", "--method", "adam"], "argument --method: invalid choice"),
    (["{trace}", "--rtol", "0.5"], "Settings.rtol must be in [1e-10, 0.1], got 0.5"),
    (["{trace}", "--rtol", "-1e-4"], "argument --rtol"),
    (["{trace}", "--order", "4"], "argument --order: invalid choice"),
    ([], "the following arguments are required: traces"),
    (["{tmp}/missing.csv"], "missing.csv: cannot read trace file"),
    (["{tmp}"], "is a folder, not a trace file"),
]


@pytest.mark.parametrize("argv, message", FIT_USAGE)
def test_fit_usage_errors_are_one_line_exit_2_before_fitting(
    argv, message, trace, tmp_path, capsys, no_run
):
    os.symlink(trace, tmp_path / "link.json")
    os.link(trace, tmp_path / "hard.csv")
    before = sorted(os.listdir(tmp_path))
    digest = _digest(trace)
    argv = [a.format(trace=trace, tmp=tmp_path, name=tmp_path.name) for a in argv]
    assert fcli.main(argv + ["--quiet"]) == 2
    line = _one_line_error(capsys.readouterr().err, "lubjax-fit")
    assert message.format(tmp=tmp_path) in line
    assert _digest(trace) == digest  # the user's data is never touched
    assert sorted(os.listdir(tmp_path)) == before
    assert os.path.islink(tmp_path / "link.json")


def _trace_text(scale_d=1.0, scale_f=1.0, header="# radius_m: 2.0e-3\n"):
    tr = read_trace(SEED)
    rows = "".join(
        f"{float(t)!r},{float(d) * scale_d!r},{float(f) * scale_f!r}\n"
        for t, d, f in zip(tr.time, tr.displacement, tr.force)
    )
    return header + "time_s,displacement_m,force_N\n" + rows


BAD_TRACES = [
    # item 4: scales the thin-film model cannot describe, named with the likely unit mistake
    (_trace_text(scale_d=1e3), "column displacement_m: the travel reaches 0.14 m"),
    (_trace_text(scale_d=1e3), "millimetres"),
    (_trace_text(scale_f=1e300), "column force_N: |force| reaches"),
    (_trace_text(header="# radius_m: 2\n"), "line 1: radius_m = 2 m is outside"),
    (_trace_text(header="# radius_m: 2000\n"), "millimetres"),
    # item 5: Poisson's ratio and duplicated header keys
    (_trace_text(header="# radius_m: 2e-3\n# poisson_ratio: 0.9\n"), "line 2: poisson_ratio"),
    (_trace_text(header="# radius_m: 2e-3\n# poisson_ratio: half\n"), "got 'half'"),
    (_trace_text(header="# radius_m: 2e-3\n# x: 1\n# radius_m: 3e-3\n"), "lines 1 and 3 both"),
]


@pytest.mark.parametrize("text, message", BAD_TRACES)
def test_fit_refuses_nonsense_traces(text, message, tmp_path, capsys, no_run):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(TraceError, match=None) as info:
        read_trace(p)
    assert message in str(info.value) and str(p) in str(info.value)
    out = tmp_path / "new" / "fit.json"
    assert fcli.main([str(p), "--out", str(out), "--quiet"]) == 2
    assert message in _one_line_error(capsys.readouterr().err, "lubjax-fit")
    assert os.listdir(tmp_path) == ["bad.csv"]  # no output folder made for a refused input


ENCODINGS = [
    # item 6: a BOM is fine; other encodings and binary files are named with their line
    (b"\xef\xbb\xbf", None, None),
    (b"", "latin-1", "line 2: not UTF-8 text (byte 0xb5)"),
    (b"\xff\xfe", "utf-16-le", "line 1: the file is UTF-16 text"),
    (b"\x89PNG\r\n\x1a\n\x00\x00", None, "line 1: not UTF-8 text (byte 0x89)"),
    (b"\x00\x01\x02", None, "line 1: NUL byte"),
]


@pytest.mark.parametrize("prefix, encoding, message", ENCODINGS)
def test_encodings(prefix, encoding, message, tmp_path, capsys, no_run):
    text = _trace_text(header="# radius_m: 2.0e-3\n# probe: 5 µm\n")
    p = tmp_path / "enc.csv"
    p.write_bytes(prefix + text.encode(encoding or "utf-8"))
    if message is None:
        tr = read_trace(p)
        assert tr.radius == 2e-3 and tr.metadata["probe"] == "5 µm"
        return
    with pytest.raises(TraceError) as info:
        read_trace(p)
    assert f"{p}: {message}" in str(info.value)
    assert fcli.main([str(p), "--quiet"]) == 2
    assert message in _one_line_error(capsys.readouterr().err, "lubjax-fit")


def test_fit_per_trace_plots_of_same_named_traces_do_not_collide(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(fcli, "fit_traces", _fake_fit)
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        shutil.copy(SEED, tmp_path / sub / "run.csv")
    traces = [str(tmp_path / "a" / "run.csv"), str(tmp_path / "b" / "run.csv")]
    plot = tmp_path / "out" / "fits.png"
    assert fcli.plot_paths(str(plot), traces) == [
        str(tmp_path / "out" / "fits_a_run.png"),
        str(tmp_path / "out" / "fits_b_run.png"),
    ]
    # names that still clash after that are numbered
    clash = fcli.plot_paths("f.pdf", ["x_y.csv", "x/y.csv"])
    assert len(set(clash)) == 2 and all(p.endswith(".pdf") for p in clash)
    out, table = tmp_path / "out" / "fits.json", tmp_path / "out" / "fits.csv"
    argv = traces + ["--out", str(out), "--table", str(table), "--plot", str(plot), "--quiet"]
    assert fcli.main(argv) == 0
    assert sorted(os.listdir(tmp_path / "out")) == [
        "fits.csv", "fits.json", "fits_a_run.png", "fits_b_run.png"
    ]  # fmt: skip
    assert [d["trace"] for d in json.loads(out.read_text())] == traces
    assert len(table.read_text().splitlines()) == 3
    assert "wrote" in capsys.readouterr().out


def test_fit_rtol_and_order_reach_the_model_settings(monkeypatch, capsys):
    """--rtol and --order change only the tolerance and the integrator of the fits' settings
    (FIT_SETTINGS' force floor and step budget stay); without them the fit gets no settings,
    i.e. FIT_SETTINGS."""
    import fitting

    seen = []

    def capture(traces, **kwargs):
        seen.append(kwargs.get("settings"))
        return _fake_fit(traces)

    monkeypatch.setattr(fcli, "fit_traces", capture)
    assert fcli.main([SEED, "--quiet", "--rtol", "1e-5"]) == 0
    assert fcli.main([SEED, "--quiet"]) == 0
    assert fcli.main([SEED, "--quiet", "--order", "3"]) == 0
    tight, default, bdf3 = seen
    assert tight.rtol == 1e-5 and default is None
    assert tight == dataclasses.replace(fitting.FIT_SETTINGS, rtol=1e-5)
    assert bdf3 == dataclasses.replace(fitting.FIT_SETTINGS, order=3)


def test_fit_not_converged_is_exit_1_with_outputs(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(
        fcli, "fit_traces", lambda tr, **k: [r._replace(converged=False) for r in _fake_fit(tr)]
    )
    out = tmp_path / "fit.json"
    assert fcli.main([SEED, "--out", str(out), "--quiet"]) == 1
    assert "NOT CONVERGED" in capsys.readouterr().out
    assert json.loads(out.read_text())["converged"] is False


def test_fit_failed_plot_write_keeps_old_file(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(fcli, "fit_traces", _fake_fit)
    plot = tmp_path / "fit.png"
    plot.write_bytes(b"old picture")

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(_files.os, "fsync", full_disk)
    assert fcli.main([SEED, "--plot", str(plot), "--quiet"]) == 1
    line = _one_line_error(capsys.readouterr().err, "lubjax-fit")
    assert "cannot write" in line and "No space left" in line
    assert plot.read_bytes() == b"old picture"
    assert os.listdir(tmp_path) == ["fit.png"]


def test_fit_value_error_during_fit_is_exit_2(monkeypatch, capsys):
    def bad(*args, **kwargs):
        raise ValueError("trace.csv: column displacement_m: the travel never settles into a hold")

    monkeypatch.setattr(fcli, "fit_traces", bad)
    assert fcli.main([SEED]) == 2  # progress line on: it is cleared, the error stays one line
    err = capsys.readouterr().err
    assert err.count("lubjax-fit: error:") == 1 and "never settles" in err.splitlines()[-1]


def test_large_trace_is_read_by_numpy_not_line_by_line(tmp_path, monkeypatch):
    """Item 10: a good file never reaches the line-by-line parser (only a bad one does)."""
    import fitting._csv as io_mod

    def slow(*args, **kwargs):
        raise AssertionError("good file parsed line by line")

    tr = read_trace(SEED)
    monkeypatch.setattr(io_mod, "parse_trace", slow)
    fast = read_trace(SEED)
    np.testing.assert_array_equal(fast.force, tr.force)
    assert fast.metadata == parse_trace(open(SEED).read(), SEED).metadata
    assert io_mod.MAX_FILE_BYTES == 1 << 30


def test_atomic_open_unit(tmp_path):
    p = tmp_path / "x.txt"
    p.write_text("old")
    with pytest.raises(_files.WriteError, match="x.txt"):
        with _files.atomic_open(p) as fh:
            fh.write("new, half")
            raise OSError(errno.EIO, "I/O error")
    with pytest.raises(RuntimeError):
        with _files.atomic_open(p) as fh:
            fh.write("new, half")
            raise RuntimeError("writer bug")
    assert p.read_text() == "old" and os.listdir(tmp_path) == ["x.txt"]
    os.chmod(p, 0o640)
    _files.write_text(p, "new")
    assert p.read_text() == "new" and os.stat(p).st_mode & 0o777 == 0o640


# --------------------------------------------------------------------------- end to end


def _run(*argv):
    return subprocess.run([sys.executable, *argv], capture_output=True, text=True, cwd=ROOT)


def test_end_to_end_exit_codes(tmp_path):
    proc = _run("-m", "lubjax", "relax", "--beta", "100", "--z0", "0.5", "--plot", "figplain")
    assert proc.returncode == 2 and proc.stdout == ""
    _one_line_error(proc.stderr, "lubjax")
    copy = tmp_path / "t.csv"
    shutil.copy(SEED, copy)
    proc = _run("-m", "fitting", str(copy), "--out", str(copy))
    assert proc.returncode == 2 and "is the input trace" in proc.stderr
    _one_line_error(proc.stderr, "lubjax-fit")
    assert _digest(copy) == _digest(SEED)


def test_end_to_end_real_relax_run(tmp_path, capsys):
    """One real (short) run: JSON and PDF written whole, nothing else left in the folder."""
    out, plot = tmp_path / "run.json", tmp_path / "run.pdf"
    out.write_text("old")
    assert lcli.main(DIM + ["--t-end", "0.5", "--out", str(out), "--plot", str(plot)]) == 0
    data = json.loads(out.read_text())
    assert data["t"][-1] == pytest.approx(0.5) and len(data["force"]) == len(data["t"])
    assert plot.read_bytes().startswith(b"%PDF")
    assert sorted(os.listdir(tmp_path)) == ["run.json", "run.pdf"]
    assert "wrote" in capsys.readouterr().out

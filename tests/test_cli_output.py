"""What the command lines show: units, names, progress lines, --help examples, and the fit and
model-comparison reports. The report and format functions are tested on constructed results;
a few runs are real (short, coarse)."""

from __future__ import annotations

import io
import os
import shlex
import sys
import time
from types import SimpleNamespace

import numpy as np
import pytest

import fitting._compare as fcompare
import lubjax._cli as lcli
import lubjax._cli_output as lout
import lubjax._plotting as lplot
import lubjax._solve as lsolve
from fitting import _cli as fcli
from fitting._fit import FitResult
from fitting._model import ModelSpec, to_theta
from fitting._problem import make_layout
from fitting._report import fit_report, short_value, summary_line
from fitting._scales import Scales
from fitting._start import Start
from lubjax import RelaxationTest

from helpers import DATA
from helpers import SEED_TRACE as SEED

CONTROL = ("\r", "\x1b")


class _Terminal(io.StringIO):
    def isatty(self):
        return True


# --------------------------------------------------------------------------- constructed fits


def _fit_result(spec=None, name="trace.csv", values=None, stderr=None, start=None, shared=(),
                group=(), n_parameters=None, log_likelihood=0.0, converged=True):
    spec = spec or ModelSpec()
    base = dict(E_star=3.9e6, viscosity=100.0, z0=1.4e-4, stiffening=1.5, relaxation_time=0.5,
                offset=-5e-7)
    errs = dict(E_star=5e4, viscosity=0.4, z0=4e-8, stiffening=0.022, relaxation_time=0.02,
                offset=2.2e-5)
    values = {n: (values or {}).get(n, base[n]) for n in spec.names}
    stderr = {n: (stderr or {}).get(n, errs[n]) for n in spec.names}
    k = len(spec.names) if n_parameters is None else n_parameters
    stats = dict(n_samples=1754, n_parameters=k, chi2=1700.0, reduced_chi2=0.97,
                 autocorrelation_lag1=0.0, durbin_watson=2.0, noise_model="white",
                 n_effective=1754.0, log_likelihood=log_likelihood, aic=2 * k, bic=7.5 * k,
                 rms_residual=3.6e-4, noise_sigma=3.6e-4, condition=10.0, max_correlation=0.5,
                 error_parts={})
    t = np.linspace(0.0, 17.5, 50)
    return FitResult(
        name=name, spec=spec, values=values, stderr=stderr,
        correlation=np.eye(len(spec.names)), shared=tuple(shared), group=tuple(group),
        scales=Scales(1.4e-4, 1e-4, 2e-3, 1.0, 1.4, 1.0, 0.036, 1.4e-4), stats=stats,
        converged=converged, identifiable=True, n_iterations=5, n_model_runs=6, method="lm",
        wall_s=1.0, start=start or Start(dict(values), ("from the data",)), flags=("ok",),
        time=t, data=np.zeros_like(t), model=np.zeros_like(t), metadata={},
    )  # fmt: skip


LAYER = ModelSpec(layer=(5e-3, 0.5, "bonded"))
VISCO = ModelSpec(viscoelastic=True)


def test_comparison_of_models_with_equal_parameter_counts_claims_no_extra_parameters():
    simple = [_fit_result(log_likelihood=-22.5)]
    layer = [_fit_result(LAYER, log_likelihood=-13.6)]
    cmp = fcompare.compare(simple, layer, "elastic half-space", LAYER.substrate_label())
    text = "\n".join(cmp["report"])
    assert cmp["choice"] == cmp["rich"]  # ΔBIC = 2 Δℓ = 17.8 > 10
    assert "0 extra" not in text and "nan" not in text and "extra parameters" not in text
    assert cmp["p_value_nominal"] is None and "not nested" in text
    assert "the data favour it over the elastic half-space" in cmp["report"][-1]
    cmp = fcompare.compare(simple, [_fit_result(LAYER, log_likelihood=-20.0)],
                           "elastic half-space", LAYER.substrate_label())
    assert cmp["choice"] == cmp["simple"] and "extra parameters" not in cmp["report"][-1]


def test_comparison_of_nested_models_reports_the_extra_parameters_and_a_p_value():
    cmp = fcompare.compare([_fit_result(log_likelihood=-128.4)],
                           [_fit_result(VISCO, log_likelihood=100.1)], "elastic", "visco")
    assert "on 2 extra parameter(s), nominal p = " in cmp["report"][2]
    assert 0 <= cmp["p_value_nominal"] < 1e-50
    assert "the data ask for the extra parameters" in cmp["report"][-1]


def _recording_fit(calls):
    """A stand-in for fit_traces: records its keywords, reports progress, returns results."""

    def fit(traces, *, spec, starts=None, progress=None, **kwargs):
        calls.append(dict(spec=spec, starts=starts))
        if progress is not None:
            progress("iteration 1, chi2/2 900, 0/1 done")
        return [_fit_result(spec, name=tr.name if hasattr(tr, "name") else "t.csv",
                            log_likelihood=-10.0 * len(calls)) for tr in traces]

    return fit


def test_layer_comparison_starts_are_not_viscoelastic_and_progress_names_the_model(
        monkeypatch):
    calls, seen = [], []
    monkeypatch.setattr(fcompare, "fit_traces", _recording_fit(calls))
    simple, rich, _ = fcompare.compare_models(
        [SimpleNamespace(name="a.csv")], simple=ModelSpec(), rich=LAYER, progress=seen.append)
    notes = " ".join(calls[1]["starts"][0].notes)
    assert "E0/Einf" not in notes and "tau" not in notes and "elastic half-space" in notes
    assert "E0/Einf" not in fit_report(rich[0]).split("[[Start values]]")[1]
    assert seen == ["elastic half-space: iteration 1, chi2/2 900, 0/1 done",
                    f"{LAYER.substrate_label()}: iteration 1, chi2/2 900, 0/1 done"]
    calls.clear()
    fcompare.compare_models([SimpleNamespace(name="a.csv")], simple=ModelSpec())
    notes = " ".join(calls[1]["starts"][0].notes)
    assert "E0/Einf = 1.2" in notes and calls[1]["starts"][0].values["stiffening"] == 1.2


def test_units_are_not_repeated_and_offsets_get_no_relative_error():
    res = _fit_result(VISCO)
    line = summary_line(res)
    assert line.count("E0/Einf") == 1 and "E0/Einf = 1.5 ± 0.022, tau" in line
    assert short_value(res, "stiffening") == "1.5 ± 0.022"
    assert short_value(res, "E_star") == "3.9 ± 0.05 MPa"
    report = fit_report(res)
    rows = {ln.split()[0]: ln for ln in report.splitlines() if " +/- " in ln}
    # absolute error only, in the unit its size reads best in (22 uN here)
    assert "%" not in rows["offset"] and " uN " in rows["offset"]
    assert "(1.28%)" in rows["E_star"]  # scale parameters keep their relative error
    assert "E0/Einf" not in rows["stiffening"] and "stiffening = E0/Einf" in report


def test_display_units_follow_the_size_of_the_value():
    """A gel on an AFM (E* ~ 100 Pa, forces of nN) is not printed as 0.0001 MPa."""
    from fitting._report import units

    res = _fit_result(VISCO)
    soft = res._replace(values={**res.values, "E_star": 106.0, "offset": 2e-10},
                        stderr={**res.stderr, "E_star": 1.0, "offset": 5e-11})
    assert units(soft, "E_star") == ("E_star_Pa", "Pa", 1.0)
    assert units(soft, "offset") == ("offset_N", "nN", 1e-9)
    assert short_value(soft, "E_star") == "106 ± 1 Pa"
    mid = res._replace(values={**res.values, "E_star": 2.5e4})
    assert units(mid, "E_star")[1] == "kPa"
    assert units(res, "E_star")[1] == "MPa"


def test_joint_fit_reports_one_start_for_a_shared_parameter():
    from fitting._fit import _start_used

    spec = ModelSpec()
    own = [dict(E_star=6.75e6, viscosity=99.1, z0=1.42e-4, offset=1.9e-5),
           dict(E_star=3.73e6, viscosity=100.7, z0=1.44e-4, offset=-4e-5)]
    theta0 = np.array([[to_theta(n, v[n], 1e-3) for n in spec.names] for v in own])
    shared = ("E_star", "viscosity")
    layout, x0s = make_layout([[0, 1]], spec, ["a", "b"], theta0, shared)
    scales = Scales(1.4e-4, 1e-4, 2e-3, 1.0, 1.4, 1.0, 1e-3, 1.4e-4)
    starts = [_start_used(Start(v, ("guess",)), spec, layout, t, x0s[0], scales, shared)
              for t, v in enumerate(own)]
    for n in shared:
        assert starts[0].values[n] == pytest.approx(starts[1].values[n], rel=1e-12)
    assert starts[0].E_star == pytest.approx(np.sqrt(6.75e6 * 3.73e6), rel=1e-12)
    assert [s.z0 for s in starts] == [1.42e-4, 1.44e-4]  # per trace: its own start
    assert "one start for all traces" in starts[1].notes[-1]
    reports = [fit_report(_fit_result(spec, start=s, shared=shared, group=("a", "b")))
               for s in starts]
    inits = [[ln.split("init = ")[1] for ln in r.splitlines() if ln.lstrip().startswith("E_star")]
             for r in reports]
    assert inits[0] == inits[1]


# --------------------------------------------------------------------------- lubjax-fit


def _fake_fit_traces(traces, **kwargs):
    progress = kwargs.get("progress")
    for it in range(3):
        progress(f"iteration {it}, chi2/2 1, 0/1 done")
    return [_fit_result(kwargs.get("spec"), name=tr.name) for tr in traces]


def test_the_command_line_reads_scales_and_starts_once_and_the_fit_takes_them(monkeypatch):
    """The start warnings' scales and starts are the fit's: computed once, passed along."""
    import fitting._scales as fscales
    import fitting._start as fstart

    reads, calls = [], []
    read = fscales.scales_from_trace
    monkeypatch.setattr(fscales, "scales_from_trace",
                        lambda tr, drive=None: reads.append(tr.name) or read(tr, drive))
    monkeypatch.setattr(fcli, "fit_traces",
                        lambda traces, **kw: calls.append(kw) or _fake_fit_traces(traces, **kw))
    monkeypatch.setattr(fcli, "enable_compilation_cache", lambda: None)
    assert fcli.main([SEED, "--quiet"]) == 0
    assert reads == [SEED]
    (kw,) = calls
    assert isinstance(kw["scales"][0], Scales) and isinstance(kw["starts"][0], Start)
    tr = fcli.read_trace(SEED)
    _, scales, starts = fstart.prepare_starts([tr], kw["spec"], (), None, kw["starts"],
                                              kw["scales"])
    assert reads == [SEED] and scales == kw["scales"] and starts == kw["starts"]


def test_fit_progress_in_a_log_has_no_control_characters_nor_a_cold_start_claim(
        monkeypatch, capsys):
    monkeypatch.setattr(fcli, "fit_traces", _fake_fit_traces)
    monkeypatch.setattr(fcli, "enable_compilation_cache", lambda: "/cache")  # a warm run?
    assert fcli.main([SEED]) == 0
    err = capsys.readouterr().err
    assert not any(c in err for c in CONTROL), repr(err)
    lines = err.splitlines()
    assert len(lines) == 4 and lines[-1].endswith("iteration 2, chi2/2 1, 0/1 done")
    assert "first call only" not in err and "or loading it from the cache" in err


def test_fit_progress_on_a_terminal_redraws_one_line(monkeypatch, capsys):
    monkeypatch.setattr(fcli, "fit_traces", _fake_fit_traces)
    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    assert fcli.main([SEED, "--no-cache"]) == 0
    err = terminal.getvalue()
    assert err.count("\r\x1b[K") == 5 and err.endswith("\r\x1b[K") and "\n" not in err
    assert "compiling the solver" in err  # no cache: it is compiled


def test_fit_progress_under_compare_names_the_model(monkeypatch, capsys):
    monkeypatch.setattr(fcompare, "fit_traces", _recording_fit([]))
    assert fcli.main([SEED, "--compare"]) in (0, 1)
    err = capsys.readouterr().err
    assert "] elastic half-space: iteration 1" in err
    assert "] viscoelastic (standard linear solid) half-space: iteration 1" in err


def test_fit_help_states_the_format_and_ends_with_examples(capsys):
    assert fcli.main(["--help"]) == 0
    out = capsys.readouterr().out
    for item in ("time_s", "displacement_m", "force_N", "# radius_m:",
                 "the trace file format page of the documentation,\ndocs/guide/trace-format.md"):
        assert item in out
    assert "README" not in out
    assert len(_examples(out, "lubjax-fit")) >= 2


# --------------------------------------------------------------------------- --help examples


def _examples(help_text, prog):
    """The commands of the help's closing "examples" block (it must end the help)."""
    block = help_text.rstrip().split("\nexamples")[-1].split("\n", 1)[1]
    commands = block.replace("\\\n", " ").splitlines()
    assert all(c.strip().startswith(prog + " ") for c in commands), commands
    return [shlex.split(c)[1:] for c in commands]


class _Reached(Exception):
    pass


@pytest.mark.parametrize("command", [[], ["relax"], ["creep"], ["bounce"]])
def test_lubjax_help_ends_with_examples_that_pass_every_check(command, capsys, monkeypatch,
                                                              tmp_path):
    assert lcli.main([*command, "--help"]) == 0
    examples = _examples(capsys.readouterr().out, "lubjax")
    assert 2 <= len(examples) <= 3

    def reached(*args, **kwargs):
        raise _Reached

    monkeypatch.setattr(lsolve, "relax", reached)
    monkeypatch.chdir(tmp_path)
    for argv in examples:
        with pytest.raises(_Reached):  # every input check passed: the solver was called
            lcli.main([*argv, "--debug"])


def test_fit_help_examples_run(capsys, monkeypatch, tmp_path):
    assert fcli.main(["--help"]) == 0
    examples = _examples(capsys.readouterr().out, "lubjax-fit")
    monkeypatch.setattr(fcli, "fit_traces", _fake_fit_traces)
    monkeypatch.setattr(fcompare, "fit_traces", _recording_fit([]))
    monkeypatch.chdir(tmp_path)
    os.symlink(DATA, tmp_path / "data")
    for argv in examples:
        assert fcli.main(argv) == 0, capsys.readouterr().err


# --------------------------------------------------------------------------- lubjax relax


SI_TEST = RelaxationTest(3.92e6, 2e-3, 100.0, 1e-4, 140e-6, 140e-6)


def _relax_result(t_end=5.0, n=41):
    t = np.linspace(0.0, t_end, n)
    force = np.where(t < 1, t, np.exp(1 - t))
    r = np.linspace(0.0, 3.0, 30)
    return SimpleNamespace(
        t=t, force=force, film_min=1.0 / (1 + t), film_center=1.2 / (1 + t), beta=53.9, z0=1.0,
        force_error=np.full(n, 1e-3), accepted=n - 1, rejected=2, run_s=0.1, compile_s=1.0,
        r=r, profile_times=np.array([1.0, t_end]), pressure=np.ones((2, 30)),
        film=np.ones((2, 30)), gap=1.0 - np.minimum(t, 1.0), film_min_error=np.zeros(n),
        film_center_error=np.zeros(n), ok=True, unresolved_film=lambda: None, problems=list,
    )  # fmt: skip


def test_relax_summary_in_si_units():
    res = _relax_result()
    line = lout.relax_summary(res, SI_TEST)
    t_c, f_s = SI_TEST.time_scale, SI_TEST.force_scale
    assert f"peak {f_s:.5g} N at t = {t_c:.4g} s" in line
    assert f"force at t = {5 * t_c:.4g} s {res.force[-1] * f_s:.5g} N" in line
    assert f"thinnest film {1 / 6 * 140:.3g} um" in line
    assert "F(t_end)" not in line
    assert "F(t_end)=" in lout.relax_summary(res)  # dimensionless mode stays dimensionless


def _captured_figure(monkeypatch):
    figures = []
    monkeypatch.setattr(lplot, "save_figure", lambda fig, path, **kw: figures.append(fig))
    return figures


def _labels(fig):
    return [a.get_xlabel() + " | " + a.get_ylabel() for a in fig.axes]


def test_relax_figure_in_si_units_names_drive_and_substrate(monkeypatch):
    figures = _captured_figure(monkeypatch)
    lplot.plot_result(_relax_result(), "x.png", test=SI_TEST, substrate="bonded layer H = 5 mm")
    lplot.plot_result(_relax_result(), "y.png")
    si, dimensionless = figures
    assert _labels(si)[0] == "t [s] | force F [mN]"
    assert _labels(si)[2] == "r [mm] | pressure p [kPa]"
    assert "[μm]" in _labels(si)[1]
    line = si.axes[0].get_lines()[0]
    np.testing.assert_allclose(line.get_xdata()[-1], 5 * SI_TEST.time_scale)
    np.testing.assert_allclose(np.max(line.get_ydata()), SI_TEST.force_scale * 1e3)
    title = si.get_suptitle()
    assert "travel ramped" in title and "substrate: bonded layer H = 5 mm" in title
    assert "substrate: elastic half-space" in dimensionless.get_suptitle()
    assert "travel ramped" in dimensionless.get_suptitle()
    assert _labels(dimensionless)[0] == "t̄ | F̄"


def test_relax_progress_line_only_on_a_terminal(monkeypatch, capsys):
    monkeypatch.setattr(lout, "PROGRESS_AFTER_S", 0.0)
    monkeypatch.setattr(lout, "PROGRESS_EVERY_S", 0.01)

    def relax(*args, progress, **kwargs):  # tells its phases as the solver's relax does
        for phase in ("compiling the solver", "running the solver"):
            progress(phase)
            # hold the phase until the line shows it (a loaded machine schedules the redraw
            # late), or 0.2 s where stderr is not a terminal
            deadline = time.perf_counter() + (10.0 if sys.stderr.isatty() else 0.2)
            while time.perf_counter() < deadline and not (
                    sys.stderr.isatty() and phase in sys.stderr.getvalue()):
                time.sleep(0.01)
        return _relax_result()

    monkeypatch.setattr(lsolve, "relax", relax)
    argv = ["relax", "--beta", "100", "--z0", "0.5"]
    assert lcli.main(argv) == 0
    assert capsys.readouterr().err == ""  # not a terminal: nothing
    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    assert lcli.main(argv) == 0
    err = terminal.getvalue()
    assert "relax: compiling the solver ..." in err
    assert "relax: running the solver ..." in err
    assert err.index("compiling") < err.index("running") and err.endswith("\r\x1b[K")
    assert "[   0.0 s]" in err


def test_short_run_shows_no_progress_line(monkeypatch):
    monkeypatch.setattr(lsolve, "relax", lambda *a, **k: _relax_result())
    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    assert lcli.main(["relax", "--beta", "100", "--z0", "0.5"]) == 0
    assert terminal.getvalue() == ""


# --------------------------------------------------------------------------- lubjax bounce


def test_bounce_summary_names_what_can_go_below_zero():
    from lubjax._units import Collision

    test = Collision(1e6, 2e-3, 0.01, 2.6e-4, 0.05, 50e-6)
    t = np.linspace(0, 20, 201)
    gap = np.cos(t / 3)  # dips to -1: the rigid-body position under the undeformed surface
    res = SimpleNamespace(t=t, gap=gap, film_min=0.03 + 0.01 * (t - 8) ** 2 / 64,
                          force=np.exp(-((t - 9) ** 2)), accepted=200, run_s=0.1, compile_s=1.0)
    line = lout.bounce_summary(res, test, 0.4)
    assert "closest gap" not in line
    assert "minimum film thickness 1.5 um at t = 0.008 s" in line
    assert "lowest sphere position (rigid body) z = -50 um" in line
    assert "below the undeformed surface" in line
    assert f"peak film force {test.force_scale:.4g} N at t = 0.009 s" in line


def test_bounce_figure_shows_the_pressure_at_impact(tmp_path, monkeypatch, capsys):
    figures = _captured_figure(monkeypatch)
    argv = ["bounce", "--E-star", "1e6", "--viscosity", "0.01", "--radius", "2e-3",
            "--density", "7800", "--speed", "0.05", "--gap", "50e-6", "--rtol", "1e-3",
            "--plot", str(tmp_path / "b.png")]  # fmt: skip
    seen = []
    real = lsolve.relax
    monkeypatch.setattr(lsolve, "relax", lambda *a, **k: seen.append(real(*a, **k)) or seen[-1])
    assert lcli.main(argv) == 0
    out = capsys.readouterr().out
    assert "closest gap" not in out and "minimum film thickness" in out
    first = seen[0]
    ts = 50e-6 / 0.05
    impact = first.t[np.argmax(first.force)] * ts
    lines = figures[0].axes[3].get_lines()
    labels = [ln.get_label() for ln in lines]
    assert labels[0] == f"t = {impact:.3g} s (impact: peak force)"
    assert labels[1].endswith("(end)")
    # at impact the film carries the peak force: its pressure far above the end's
    assert np.max(lines[0].get_ydata()) > 10 * np.max(np.abs(lines[1].get_ydata()))
    assert "substrate: elastic half-space" in figures[0].get_suptitle()


def test_relax_tells_its_phases_in_order():
    """What the progress line shows comes from relax itself, not from guessing."""
    import lubjax

    phases = []
    lubjax.relax(100.0, 0.5, 1.0, settings=lubjax.Settings(rtol=1e-3), progress=phases.append)
    assert phases == ["compiling the solver", "running the solver", "estimating the error"]
    quiet = []
    lubjax.relax(100.0, 0.5, 1.0, settings=lubjax.Settings(rtol=1e-3, error_estimate=False),
                 progress=quiet.append)
    assert quiet == ["compiling the solver", "running the solver"]


def test_relax_json_carries_the_runs_problems_and_film_note(tmp_path):
    """The JSON says what relax's message and Result.problems() say, in the same words."""
    import json

    import lubjax._cli as lcli_mod

    out = tmp_path / "run.json"
    assert lcli_mod.main(["relax", "--beta", "100", "--z0", "0.5", "--t-end", "1",
                          "--rtol", "1e-3", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["ok"] and data["problems"] == [] and data["unresolved_film"] is None


@pytest.mark.slow
def test_relax_holds_a_near_dry_film_through_the_force_by_default(tmp_path):
    """β = 10⁶ indenting: the default (--film-error auto) is the force norm's run, step for
    step (the JSON's count), fewer steps than --film-error relative, and the same force (its
    peak within 1e-3)."""
    import json

    runs = {}
    for mode in (None, "force", "relative"):
        out = tmp_path / f"{mode}.json"
        extra = [] if mode is None else ["--film-error", mode]
        assert lcli.main(["relax", "--beta", "1e6", "--z0", "0.5", "--t-end", "1.2", "--rtol",
                          "1e-3", *extra, "--out", str(out)]) == 0
        runs[mode] = json.loads(out.read_text())
    assert runs[None]["settings"]["film_error"] == "auto"
    assert runs[None]["steps"] == runs["force"]["steps"] < runs["relative"]["steps"]
    peaks = [max(runs[m]["force"]) for m in (None, "relative")]
    assert abs(peaks[0] - peaks[1]) < 1e-3 * peaks[0]

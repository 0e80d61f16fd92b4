"""``lubjax creep`` and ``lubjax bounce``: end-to-end runs against physics, and bad input refused
before anything runs (one line, exit 2)."""

import json

import numpy as np
import pytest

import lubjax
import lubjax._cli as lcli
import lubjax._solve as lsolve

MATERIAL = ["--E-star", "3.92e6", "--viscosity", "100", "--radius", "2e-3"]
CREEP = ["creep", *MATERIAL, "--load", "0.03", "--ramp-time", "1", "--hold", "1", "--gap", "140e-6"]
BOUNCE = ["bounce", *MATERIAL, "--mass", "1e-3", "--speed", "0.1", "--gap", "1e-4"]


def _error(capsys):
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_creep_cli_reaches_hertz_and_writes_json(tmp_path):
    out = tmp_path / "creep.json"
    argv = ["creep", *MATERIAL, "--load", "0.03", "--ramp-time", "1", "--hold", "59",
            "--gap", "140e-6", "--rtol", "1e-3", "--out", str(out)]  # fmt: skip
    assert lcli.main(argv) == 0
    data = json.loads(out.read_text())
    delta = lubjax.hertz_indentation(3.92e6, 2e-3, 0.03)
    assert data["hertz_indentation_m"] == pytest.approx(delta)
    np.testing.assert_allclose(data["force_N"][-1], 0.03, rtol=1e-9)
    # After 60 s the sphere has approached by z0 + δ∞ less the film still trapped (~1 μm).
    left = 140e-6 + delta - data["approach_m"][-1]
    assert 0 < left < 0.02 * (140e-6 + delta)
    assert left == pytest.approx(data["h_center_m"][-1], rel=0.5)
    for key in ("t_s", "gap_m", "h_min_m", "gap_error_m", "scales", "steps"):
        assert key in data


def test_creep_from_a_load_csv(tmp_path):
    csv = tmp_path / "load.csv"
    t = np.linspace(0, 5, 51)
    f = 0.02 * np.clip(t / 0.5, 0, 1)
    csv.write_text("time_s,force_N\n" + "\n".join(f"{a:.6g},{b:.6g}" for a, b in zip(t, f)))
    out = tmp_path / "c.json"
    argv = ["creep", *MATERIAL, "--load-csv", str(csv), "--gap", "100e-6", "--rtol", "1e-3",
            "--out", str(out)]  # fmt: skip
    assert lcli.main(argv) == 0
    data = json.loads(out.read_text())
    assert data["t_s"][-1] == pytest.approx(5.0)
    # The load at every step is the monotone cubic through the samples (exact at them).
    shape = lubjax.SampledTravel(t / 0.5, f / 0.02)
    expected = 0.02 * np.asarray(shape.travel(np.asarray(data["t_s"]) / 0.5))
    np.testing.assert_allclose(data["force_N"], expected, rtol=1e-9, atol=1e-15)
    assert set(np.round(data["t_s"], 12)) >= {0.5}  # the end of the ramp is a breakpoint


def test_bounce_cli_reports_restitution(tmp_path):
    out = tmp_path / "b.json"
    argv = ["bounce", "--E-star", "1e6", "--viscosity", "0.01", "--radius", "2e-3",
            "--density", "7800", "--speed", "0.05", "--gap", "50e-6", "--rtol", "1e-3",
            "--out", str(out)]  # fmt: skip
    assert lcli.main(argv) == 0
    data = json.loads(out.read_text())
    assert 0 < data["restitution"] < 1
    assert data["stokes"] == pytest.approx(7800 * 4 / 3 * np.pi * 2e-3**3 * 0.05
                                           / (6 * np.pi * 0.01 * 4e-6))
    assert min(data["velocity_m_s"]) == pytest.approx(-0.05, rel=1e-6)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["creep", *MATERIAL, "--ramp-time", "1", "--hold", "5", "--gap", "1e-4"],
         "needs --load"),
        (["creep", *MATERIAL, "--load", "-0.03", "--ramp-time", "1", "--hold", "5"],
         "--load: must be"),
        (["creep", *MATERIAL, "--load", "0.03", "--ramp-time", "1", "--hold", "-1",
          "--gap", "1e-4"], "--hold must be >= 0"),
        (["creep", *MATERIAL, "--load", "0.03", "--ramp-time", "1", "--hold", "5",
          "--gap", "0.01"], "paraboloid indenter models at most 0.2 R"),
        (["bounce", *MATERIAL, "--mass", "1e-3", "--density", "7800", "--speed", "0.1",
          "--gap", "1e-4"], "either --mass or --density"),
        (["bounce", *MATERIAL, "--mass", "1e-3", "--speed", "0.1", "--gap", "1e-4",
          "--weight", "-1"], "--weight must be >= 0"),
        # beyond the solver's longest run, said in seconds
        ([*CREEP[:-4], "--hold", "1e10", "--gap", "140e-6"], "--ramp-time + --hold = 1e+10 s "
         "is t̄ = 1e+10 (t_c = --ramp-time = 1 s); the solver runs to t̄ = 1e+09 at most, "
         "1e+09 s here: give --hold <= 9.999e+08 s"),
        ([*BOUNCE, "--t-end", "1e8"], "--t-end 1e+08 s is t̄ = 1e+11 (t_c = --gap/--speed = "
         "0.001 s); the solver runs to t̄ = 1e+09 at most, 1e+06 s here: give --t-end <= 1e+06 s"),
        (["bounce", "--viscosity", "1", "--radius", "2e-3", "--mass", "1e-3", "--speed", "0.1",
          "--gap", "1e-4"], "--E-star"),
        # the substrate options (shared with relax, issue 10 item 5)
        ([*CREEP, "--thickness", "1e-3"], "--thickness: only with --substrate layer"),
        ([*CREEP, "--prony-g", "1"], "--prony-g: only with --substrate viscoelastic"),
        ([*CREEP, "--substrate", "viscoelastic", "--prony-tau", "1"],
         "--substrate viscoelastic needs --prony-g"),
        ([*CREEP, "--substrate", "layer"], "--substrate layer needs --thickness"),
        ([*CREEP, "--substrate", "layer", "--thickness", "1e-7"], "Layer thickness H̄"),
        ([*BOUNCE, "--substrate", "viscoelastic", "--prony-g", "1", "--prony-tau", "0"],
         "--prony-tau: term 1 must be a finite number > 0 (times in s)"),
        ([*BOUNCE, "--substrate", "viscoelastic", "--prony-g", "1,1", "--prony-tau", "1"],
         "--prony-g has 2 term(s) and --prony-tau 1"),
        ([*BOUNCE, "--substrate", "layer", "--thickness", "1e-3", "--layer-poisson", "0.6"],
         "--layer-poisson must be in (-1, 0.5]"),
    ],
)  # fmt: skip
def test_bad_input_is_one_line_exit_2_before_running(argv, message, capsys, monkeypatch):
    def no_compute(*a, **k):
        raise AssertionError("computed before checking the input")

    monkeypatch.setattr(lsolve, "relax", no_compute)
    assert lcli.main(argv) == 2
    assert message in _error(capsys)


def test_creep_and_bounce_pass_the_substrate_in_their_own_units(monkeypatch, capsys):
    """Each command's d_c and t_c convert the SI substrate options: creep d_c = the Hertz
    indentation and t_c = the ramp time, bounce d_c = x0 and t_c = x0/V."""
    seen = {}

    def stop(*a, **k):  # record the solver call, then end the run as a solver failure
        seen.update(k)
        raise lsolve.SolverError("stand-in")

    monkeypatch.setattr(lsolve, "relax", stop)
    argv = [*CREEP, "--substrate", "viscoelastic", "--prony-g", "1", "--prony-tau", "0.5"]
    assert lcli.main(argv) == 1
    assert seen["substrate"].times == pytest.approx([1.0])  # λ = τ(1 + g)/t_c, t_c = 1 s
    assert isinstance(seen["drive"], lubjax.Load)
    delta = lubjax.hertz_indentation(3.92e6, 2e-3, 0.03)
    argv = [*CREEP, "--substrate", "layer", "--thickness", "1e-3", "--layer-base", "frictionless"]
    assert lcli.main(argv) == 1
    assert seen["substrate"] == lubjax.Layer(1e-3 / np.sqrt(2e-3 * delta), 0.5, "frictionless")
    argv = [*BOUNCE, "--substrate", "viscoelastic", "--prony-g", "1", "--prony-tau", "1e-3",
            "--thickness", "2e-3"]
    assert lcli.main(argv) == 1
    solid = seen["substrate"]
    assert solid.times == pytest.approx([2e-3 / (1e-4 / 0.1)])  # t_c = x0/V = 1 ms
    assert solid.elastic == lubjax.Layer(2e-3 / np.sqrt(2e-3 * 1e-4), 0.5)
    assert isinstance(seen["drive"], lubjax.FreeSphere)
    assert "on bonded layer H = 0.002 m" in capsys.readouterr().out


def test_creep_on_a_layer_approaches_less_than_on_the_half_space(tmp_path):
    """End to end: under the same load (force control, so the force is the same) the layer on its
    rigid base is stiffer than the half-space, so the sphere approaches less; the JSON records
    the layer."""
    data = {}
    for name, extra in [("half", []), ("layer", ["--substrate", "layer", "--thickness", "1e-3"])]:
        out = tmp_path / f"{name}.json"
        assert lcli.main([*CREEP, "--rtol", "1e-3", "--out", str(out), *extra]) == 0
        data[name] = json.loads(out.read_text())
    delta = lubjax.hertz_indentation(3.92e6, 2e-3, 0.03)
    assert data["half"]["substrate"] == {"kind": "halfspace"}
    assert data["layer"]["substrate"] == {
        "kind": "layer", "thickness_m": 1e-3, "poisson": 0.5, "base": "bonded",
        "thickness_bar": pytest.approx(1e-3 / np.sqrt(2e-3 * delta))}
    np.testing.assert_allclose(data["layer"]["force_N"][-1], 0.03, rtol=1e-9)
    a_half, a_layer = data["half"]["approach_m"][-1], data["layer"]["approach_m"][-1]
    assert a_layer < a_half - 0.1 * delta  # H/a ~ 4.4: a few μm less than the 25 μm indentation


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("time_s,force_N\n0,0\n1,abc\n", "load.csv:3: column 2 (force_N) is not a number"),
        ("t,F\n0,0\n1,1\n", "load.csv:1: the header must name time_s and force_N"),
        ("time_s,force_N\n0,0\n0,1\n", "time_s must increase"),
        ("time_s,force_N\n0,0\n1,0.1,3\n", "load.csv:3: 3 columns"),
    ],
)
def test_malformed_load_csv_names_line_and_column(content, message, tmp_path, capsys):
    csv = tmp_path / "load.csv"
    csv.write_text(content)
    argv = ["creep", *MATERIAL, "--load-csv", str(csv), "--gap", "1e-4"]
    assert lcli.main(argv) == 2
    assert message in _error(capsys)
    assert csv.read_text() == content

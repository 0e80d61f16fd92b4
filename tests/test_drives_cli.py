"""``lubjax creep`` and ``lubjax bounce``: end-to-end runs against physics, and bad input refused
before anything runs (one line, exit 2)."""

import json

import numpy as np
import pytest

import lubjax
import lubjax._cli as lcli
import lubjax._solve as lsolve

MATERIAL = ["--E-star", "3.92e6", "--viscosity", "100", "--radius", "2e-3"]


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
          "--gap", "0.01"], "thin-film model needs it"),
        (["bounce", *MATERIAL, "--mass", "1e-3", "--density", "7800", "--speed", "0.1",
          "--gap", "1e-4"], "either --mass or --density"),
        (["bounce", *MATERIAL, "--mass", "1e-3", "--speed", "0.1", "--gap", "1e-4",
          "--weight", "-1"], "--weight must be >= 0"),
        (["bounce", "--viscosity", "1", "--radius", "2e-3", "--mass", "1e-3", "--speed", "0.1",
          "--gap", "1e-4"], "--E-star"),
    ],
)  # fmt: skip
def test_bad_input_is_one_line_exit_2_before_running(argv, message, capsys, monkeypatch):
    def no_compute(*a, **k):
        raise AssertionError("computed before checking the input")

    monkeypatch.setattr(lsolve, "relax", no_compute)
    assert lcli.main(argv) == 2
    assert message in _error(capsys)


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

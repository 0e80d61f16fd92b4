"""Each fact in one place: the mesh rule (lubjax.mesh_for and the drives' final depth), the SI
scales (lubjax.si_scales), validation (lubjax/_checks.py), pytree registration
(lubjax/_pytree.py), the compiled-program cache (lubjax/_compiler.py) and the public surface
(lubjax.__all__, lubjax.stepper, and what fitting may import)."""

import math
import pathlib
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fitting
import lubjax
from lubjax import _checks, _compiler

COARSE = dict(dr=0.05, mesh_growth=1.2, length=50.0, error_estimate=False)
ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_relax_runs_on_the_mesh_of_mesh_for():
    settings = lubjax.Settings(**COARSE)
    res = lubjax.relax(100.0, 0.5, 1.5, settings=settings)
    mesh = lubjax.mesh_for(settings, drive=lubjax.Travel(), beta=100.0, z0=0.5, t_end=1.5)
    np.testing.assert_array_equal(res.r, mesh.r)
    # the run-dependent refinement is what tells it apart from the shared mesh of make_plan
    assert mesh.size > settings.mesh().size
    plan = lubjax.make_plan(1.5, settings=settings)
    assert plan.mesh == settings.mesh()


def test_mesh_for_without_contact_refinement_is_the_shared_mesh():
    settings = lubjax.Settings(contact_radius=None)
    for drive in (lubjax.Travel(), lubjax.Load(), lubjax.Spring(), lubjax.FreeSphere()):
        assert lubjax.mesh_for(settings, drive=drive, beta=10.0, z0=0.5, t_end=5.0) == (
            settings.mesh())


def test_drives_tell_the_mesh_rule_how_deep_they_end():
    assert lubjax.Travel().final_depth(0.25) == pytest.approx(0.75)
    t = np.linspace(0.0, 2.0, 21)
    sampled = lubjax.SampledTravel(t, np.minimum(t, 1.3))
    assert lubjax.Travel(sampled).final_depth(0.5) == pytest.approx(0.8)
    # Hertz: F̄ = (2π/3) δ̄^{3/2}, so the default load's plateau 2π/3 ends at depth 1
    assert lubjax.Load().final_depth(3.0) == pytest.approx(1.0)
    assert lubjax.Load(scale=2 * math.pi / 3 * 8).final_depth(0.1) == pytest.approx(4.0)
    # a spring ends where it balances Hertz's force: (2π/3) δ̄^{3/2} = K̄ (max d̄ - z̄0 - δ̄)
    for k in (0.1, 1.0, 30.0):
        depth = lubjax.Spring(stiffness=k).final_depth(0.5)
        assert 2 * math.pi / 3 * depth**1.5 == pytest.approx(k * (0.5 - depth), rel=1e-10)
    assert lubjax.Spring(stiffness=1e9).final_depth(0.5) == pytest.approx(0.5, rel=1e-5)
    assert lubjax.Spring().final_depth(2.0) == pytest.approx(-1.0)  # the stage stops short
    # a free sphere: Hertz's depth where its kinetic energy is stored, ½v̄0²/G = (4π/15) δ̄^{5/2},
    # or where its weight balances Hertz's force, whichever is deeper
    for g, v in ((1.0, -1.0), (0.05, -2.0)):
        depth = lubjax.FreeSphere(g, v).final_depth(0.5)
        assert 4 * math.pi / 15 * depth**2.5 == pytest.approx(0.5 * v**2 / g, rel=1e-12)
    assert 2 * math.pi / 3 * lubjax.FreeSphere(1.0, 0.0, 0.3).final_depth(1.0) ** 1.5 == (
        pytest.approx(0.3, rel=1e-12))
    assert lubjax.FreeSphere(1.0, 0.5).final_depth(1.0) == 0.0  # receding, no weight


def test_a_free_sphere_gets_its_rebound_contact_refined_and_a_spring_its_balance_edge():
    settings = lubjax.Settings()
    dr = settings.mesh_parameters()[0]
    # ε = 1e-5, St = 20: the collision's film ~2.4e-3 needs the rebound contact ~4× finer
    beta, st = 2 / (3 * math.pi**2 * 1e-5), 20.0
    sphere = lubjax.FreeSphere(2 * beta / (math.pi * st))
    free = lubjax.mesh_for(settings, drive=sphere, beta=beta, z0=1.0, t_end=12.0)
    edge = math.sqrt(sphere.final_depth(1.0))
    inside = free.r[free.r < edge]
    assert np.max(np.diff(inside)) < dr / 3
    assert np.min(np.diff(free.r)) > dr / settings.rim_refinement * (1 - 1e-9)
    # near dry the film is held through the force: the tolerance's mesh, as before
    dry = lubjax.mesh_for(settings, drive=sphere, beta=1e6, z0=1.0, t_end=12.0)
    assert np.min(np.diff(dry.r)) == pytest.approx(dr, rel=0.05)
    spring = lubjax.mesh_for(settings, drive=lubjax.Spring(), beta=1e3, z0=0.5, t_end=1e3)
    finest = np.argmin(np.diff(spring.r))
    assert np.diff(spring.r)[finest] < 0.5 * dr
    edge = math.sqrt(lubjax.Spring().final_depth(0.5))
    assert spring.r[finest] == pytest.approx(edge, abs=0.05)


def test_the_collision_film_scale_is_davis_serayssol_and_hinch():
    """h̄ ≈ 0.24 z̄0 ε^{2/5}, ε = 2|v̄0|/(3π²β z̄0^{5/2}) (2/(3π²β) in the collision's scales)."""
    beta = 2 / (3 * math.pi**2 * 1e-3)
    assert lubjax.FreeSphere(1.0).collision_film(1.0, beta) == pytest.approx(0.24 * 1e-3**0.4)
    # the same collision with d_c halved (β ∝ d_c^{3/2} t_c): z̄0 = 2, v̄0 = -2, h̄ twice
    assert lubjax.FreeSphere(1.0, -2.0).collision_film(2.0, beta / 2**1.5) == (
        pytest.approx(2 * 0.24 * 1e-3**0.4, rel=1e-12))
    assert lubjax.FreeSphere(1.0, 0.0, 0.1).collision_film(1.0, beta) is None


def test_mesh_for_checks_its_arguments():
    settings = lubjax.Settings()
    with pytest.raises(TypeError, match="as_drive"):
        lubjax.mesh_for(settings, drive=lubjax.RampHold(), beta=10.0, z0=0.5, t_end=5.0)
    with pytest.raises(ValueError, match="beta must be finite and in"):
        lubjax.mesh_for(settings, drive=lubjax.Travel(), beta=1e12, z0=0.5, t_end=5.0)
    with pytest.raises(ValueError, match="t_end must be > 0"):
        lubjax.mesh_for(settings, drive=lubjax.Travel(), beta=10.0, z0=0.5, t_end=0.0)


def test_si_scales_is_what_every_si_class_and_the_fit_use():
    test = lubjax.RelaxationTest(E_star=3.9e6, radius=2e-3, viscosity=90.0, speed=2e-6,
                                 indent=1.2e-5, gap=6e-6)
    sc = lubjax.si_scales(test.E_star, test.radius, test.indent, speed=test.speed,
                          viscosity=test.viscosity)
    assert (test.beta, test.time_scale, test.force_scale, test.pressure_scale,
            test.length_scale) == (sc["beta"], sc["time_s"], sc["force_N"], sc["pressure_Pa"],
                                   sc["length_m"])
    # F_s = 2E* d_c^{3/2} √R/π and β = E* d_c^{5/2}/(6π η v R^{3/2}) (eqs 11b, 8e)
    assert sc["force_N"] == pytest.approx(2 * 3.9e6 * 1.2e-5**1.5 * math.sqrt(2e-3) / math.pi)
    assert sc["beta"] == pytest.approx(3.9e6 * 1.2e-5**2.5 / (6 * math.pi * 90 * 2e-6
                                                             * 2e-3**1.5))
    # the time form of β is the speed form with v = d_c/t_c
    by_time = lubjax.si_scales(test.E_star, test.radius, test.indent, t_c=test.time_scale,
                               viscosity=test.viscosity)
    assert by_time["beta"] == pytest.approx(sc["beta"], rel=1e-14)
    scales = fitting.Scales(test.indent, test.speed, test.radius, 0.0, test.time_scale,
                                   1.0, 1.0, test.indent)
    assert scales.beta(test.E_star, test.viscosity) == test.beta
    assert scales.force_scale(test.E_star) == test.force_scale
    creep = lubjax.CreepTest(E_star=1e6, radius=1e-3, viscosity=1.0, load=1e-3, ramp_time=0.5,
                             gap=1e-5)
    assert "beta" not in creep.scales
    assert creep.beta == pytest.approx(
        1e6 * creep.indent**1.5 * 0.5 / (6 * math.pi * 1.0 * 1e-3**1.5), rel=1e-15)
    with pytest.raises(ValueError, match="exactly one of t_c and speed"):
        lubjax.si_scales(1.0, 1.0, 1.0)


def test_the_fits_conversions_invert_si_scales():
    """The fit's start (E* from β) and its spring (k in N/m to K̄) go through lubjax's units."""
    E, R, dc, v, eta, k = 3.9e6, 2e-3, 1.4e-4, 2e-6, 90.0, 5e3
    beta = lubjax.si_scales(E, R, dc, speed=v, viscosity=eta)["beta"]
    assert lubjax.modulus_for_beta(beta, R, dc, speed=v, viscosity=eta) == pytest.approx(
        E, rel=1e-14)
    # K̄ is k in units of F_s/d_c
    force = lubjax.si_scales(E, R, dc, speed=v)["force_N"]
    assert lubjax.spring_stiffness_bar(k, E, R, dc) == pytest.approx(k * dc / force, rel=1e-14)


def test_checks_let_tracers_through_and_name_what_is_allowed():
    @jax.jit
    def scaled(k):
        return lubjax.Spring(k).stiffness * 2.0

    assert scaled(3.0) == 6.0  # the check skips the tracer of k
    with pytest.raises(ValueError, match="Spring.stiffness must be > 0"):
        lubjax.Spring(-1.0)
    with pytest.raises(ValueError, match="'bonded' or 'frictionless', got 'glued'"):
        lubjax.Layer(1.0, 0.5, "glued")
    with pytest.raises(ValueError, match=r"Settings.order must be 1, 2 or 3, got 4"):
        lubjax.Settings(order=4)
    with pytest.raises(ValueError, match=r"nu must be in \(-1, 0.5\], got True"):
        _checks.check_poisson("nu", True)
    assert lubjax.LAYER_BASES == ("bonded", "frictionless")
    with pytest.raises(ValueError, match=r"z0 values must be finite"):
        lubjax.sweep([1.0, 2.0], [0.5, np.nan])


def test_array_and_setting_checks_name_the_parameter():
    t = np.linspace(0.0, 1.0, 5)
    with pytest.raises(ValueError, match="t and travel must be finite"):
        lubjax.SampledTravel(t, np.where(t > 0.5, np.nan, t))
    with pytest.raises(ValueError, match="t must be strictly increasing"):
        lubjax.SampledTravel(t[::-1], t)
    with pytest.raises(ValueError, match=r"breakpoints must be finite, got \(0.1, inf\)"):
        lubjax.SampledTravel(t, t, breakpoints=(0.1, math.inf))
    with pytest.raises(ValueError, match=r"Viscoelastic.times must be finite and > 0, got \[-1."):
        lubjax.Viscoelastic((0.5,), (-1.0,))
    with pytest.raises(ValueError, match=r"weight must be finite and >= 0 \(N\), got -1"):
        lubjax.Collision(1e6, 1e-3, 1.0, 1e-3, 1e-3, 1e-5, weight=-1)
    with pytest.raises(ValueError, match="weight must be a number in N, got 'heavy'"):
        lubjax.Collision(1e6, 1e-3, 1.0, 1e-3, 1e-3, 1e-5, weight="heavy")
    assert lubjax.Collision(1e6, 1e-3, 1.0, 1e-3, 1e-3, 1e-5, weight=0).weight == 0.0
    with pytest.raises(ValueError, match="Settings.max_steps must be an integer >= 10, got 10.0"):
        lubjax.Settings(max_steps=10.0)
    with pytest.raises(ValueError, match="Settings.mesh_growth must be > 0 or None, got -1"):
        lubjax.Settings(mesh_growth=-1)
    with pytest.raises(ValueError, match=r"t_end must be finite and in \(0, 1e\+09\]"):
        lubjax.make_plan(math.inf)
    with pytest.raises(ValueError, match=r"times must lie in \[0, 2\], got \[3.\]"):
        lubjax.make_plan(2.0, times=[3.0])


def test_value_classes_unflatten_without_their_checks():
    """Placeholders (here None, as vmap's in_axes trees hold) pass through tree_map."""
    for obj in (lubjax.Travel(), lubjax.Load(), lubjax.Spring(2.0), lubjax.FreeSphere(),
                lubjax.Viscoelastic.standard_linear_solid(2.0, 1.0),
                lubjax.Travel(lubjax.SampledTravel(np.linspace(0, 1, 5), np.linspace(0, 1, 5)))):
        marked = jax.tree_util.tree_map(lambda _: None, obj)
        assert type(marked) is type(obj)
    assert jax.tree_util.tree_leaves(lubjax.Layer(2.0)) == []
    spring = jax.tree_util.tree_map(jnp.asarray, lubjax.Spring(2.0))
    assert float(spring.stiffness) == 2.0


def test_the_program_cache_builds_once():
    programs, built = {}, []

    def build():
        built.append(1)
        return "program"

    first = _compiler.cached(programs, ("key",), build)
    again = _compiler.cached(programs, ("key",), build)
    assert first[0] == again[0] == "program" and again[1] == 0.0 and built == [1]
    lowered = [lambda: jax.jit(lambda x: x + 1.0).lower(1.0)] * 2
    fns, seconds = _compiler.cached_all(programs, ["a", "a"], lowered)
    assert fns[0] is fns[1] and seconds > 0
    assert _compiler.cached_all(programs, ["a"], lowered[:1])[1] == 0.0


def test_public_surface():
    for name in lubjax.__all__:
        assert hasattr(lubjax, name), name
    for name in lubjax.stepper.__all__:
        assert hasattr(lubjax.stepper, name), name
        assert name not in lubjax.__all__, name
        assert not hasattr(lubjax, name), f"lubjax.{name}: the toolkit's home is lubjax.stepper"
    assert lubjax.stepper.__doc__


def test_fitting_uses_lubjax_through_its_public_surface():
    """fitting imports lubjax.*, lubjax.stepper.* and its one declared door, lubjax._fitting_api;
    no other private lubjax module, in any spelling of the import."""
    allowed = {"_fitting_api"}
    used = set()
    for path in (ROOT / "fitting").glob("*.py"):
        text = path.read_text()
        used |= set(re.findall(r"from lubjax\.(_\w+)", text))
        used |= set(re.findall(r"from lubjax import (_\w+)", text))
        used |= set(re.findall(r"import lubjax\.(_\w+)", text))
        used |= set(re.findall(r"from \.\.(_\w+) import", text))
    assert used == allowed, used - allowed


def test_each_fitting_module_says_its_one_job_in_its_first_line_and_stays_short():
    """fitting is split by job: every module opens with a one-line docstring saying what it is
    for, and none grows past ~500 lines (a second job inside it)."""
    for path in sorted((ROOT / "fitting").glob("*.py")):
        text = path.read_text(encoding="utf-8")
        first = text.split("\n", 1)[0]
        assert re.fullmatch(r'r?""".+[.?]("""|)', first), f"{path.name}: {first!r}"
        assert text.count("\n") <= 500, f"{path.name}: {text.count(chr(10))} lines"


#: fitting's modules from the bottom up: a reader following one fit goes down this list.
FITTING_ORDER = ("_trace", "_columns", "_csv", "_afm", "_checks", "_stats", "_adequacy", "_cache",
                 "_scales", "_model", "_start", "_problem", "_profile", "_optimisers", "_fit",
                 "_report", "_figure", "_compare", "_coverage", "_cli")


def test_fitting_modules_import_only_the_ones_below_them():
    """Each fitting module imports only modules below it in FITTING_ORDER: no cycle, and no
    module that a reader of one fit must come back up to."""
    on_disk = {p.stem for p in (ROOT / "fitting").glob("_*.py")} - {"__init__", "__main__"}
    assert on_disk == set(FITTING_ORDER)
    for k, name in enumerate(FITTING_ORDER):
        text = (ROOT / "fitting" / f"{name}.py").read_text(encoding="utf-8")
        used = set(re.findall(r"^\s*from \.(_\w+) import", text, re.M))
        for names in re.findall(r"^\s*from \. import ([\w, ]+)", text, re.M):
            used |= {n.strip().split(" as ")[0] for n in names.split(",")}
        assert used <= set(FITTING_ORDER[:k]), f"{name} imports {used - set(FITTING_ORDER[:k])}"


def test_the_film_and_the_drives_are_written_once():
    """h̄ = z̄ + s(r̄) + Ŵp̄ (eq 21) and its inverse live in lubjax/_discretisation.py
    (film_thickness, elastic_part; s the indenter's profile, disc.profile, lubjax/_shape.py);
    the drives a fit knows in fitting/_trace.py (DRIVES)."""
    rigid = re.compile(r"0\.5 \* disc\.r\s*\*\*\s*2|z \+ disc\.profile|- z - disc\.profile")
    written = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "lubjax").glob("*.py")
                     if rigid.search(p.read_text(encoding="utf-8")))
    assert written == ["lubjax/_discretisation.py"]
    drives = re.compile(r"\(\s*\"travel\",\s*\"spring\",\s*\"force\"\s*\)")
    written = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "fitting").glob("*.py")
                     if drives.search(p.read_text(encoding="utf-8")))
    assert written == ["fitting/_trace.py"]
    assert fitting._scales.DRIVES is fitting._model.DRIVES is fitting._trace.DRIVES


def test_relax_and_the_fits_share_richardson_and_the_observed_orders():
    """One formula, one set of measured orders: relax's bound takes the lower ones; the fits'
    one-run estimate needs the asymptotic ones to grow alike at twice the spacing and 8 rtol."""
    from lubjax import _estimate

    assert _estimate.SPACE_ORDER == _estimate.EDGE_SPACE_ORDER
    assert _estimate.TIME_ORDER == _estimate.EULER_TIME_ORDER
    assert _estimate.LOOSENING ** _estimate.BDF2_TIME_ORDER == pytest.approx(
        2.0 ** _estimate.SMOOTH_SPACE_ORDER, rel=1e-12)
    assert lubjax.Settings(rtol=1e-4).tolerance().loosened().rtol == pytest.approx(
        _estimate.LOOSENING * 1e-4, rel=1e-15)
    assert _estimate.richardson(3.0, 2.0, 2.0) == 1.0


def test_one_drive_per_fit_is_checked_in_one_place():
    """fit_traces and lubjax-fit refuse traces of different drives with the same words."""
    import fitting
    from fitting import _cli, _scales

    t = np.linspace(0.0, 1.0, 20)
    traces = [fitting.make_trace(t, 1e-5 * t, 1e-3 * t, 2e-3, {"drive": d}, d)
              for d in ("travel", "force")]
    words = "one drive, got force, travel: fit them in separate calls"
    with pytest.raises(ValueError, match=words):
        _scales.common_drive(traces)
    with pytest.raises(_cli.UsageError, match=words):
        _cli._common_drive(traces, None)
    assert _scales.common_drive(traces, "travel") == "travel"

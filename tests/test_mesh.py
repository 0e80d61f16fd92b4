"""The mesh a run gets: refined where the late hold needs it (contact edge, contact interior, the
axis of a sphere that just touches), and not where the neck is beyond any mesh."""

import numpy as np
import pytest

import lubjax
from lubjax._mesh import (
    DRY_CONTACT_SLOPE,
    DRY_DERIVATIVE_REFINEMENT,
    DRY_RIM_REFINEMENT,
    MESH_SIZE_STEPS,
    NEAR_DRY_BETA,
    _contact_refinement,
    _interior_refinement,
    _rim_refinement,
    padded_size,
)

RAMP = lubjax.as_drive(lubjax.RampHold())


def test_refined_rim_and_contact_interior():
    dr, rim = 0.014, 0.7
    mesh = lubjax.graded_mesh(dr, 1.6, 100.0, 1.05, rim=rim, rim_dr=dr / 7, contact_dr=dr / 2)
    r = mesh.r
    cells = np.diff(r)
    at_rim = cells[np.argmin(np.abs(r[:-1] - rim))]
    assert at_rim < 1.1 * dr / 7
    inside = cells[r[1:] < rim]
    assert inside.max() <= 1.01 * dr / 2
    outside = cells[(r[:-1] > rim + 0.2) & (r[1:] <= 1.6)]
    assert outside.max() == pytest.approx(dr, rel=0.05)


def test_axis_refinement_for_a_sphere_that_just_touches():
    dr = 0.014
    mesh = lubjax.graded_mesh(dr, 1.6, 100.0, 1.05, rim=0.0, rim_dr=dr / 7)
    cells = np.diff(mesh.r)
    assert cells[0] == pytest.approx(dr / 7, rel=0.05)
    assert np.all(np.diff(cells[:20]) > 0)  # growing away from the axis
    with pytest.raises(ValueError, match="contact_dr"):
        lubjax.graded_mesh(dr, 1.6, 100.0, 1.05, contact_dr=dr / 2)


@pytest.mark.parametrize(
    "beta, z0, t_end, expected",
    [
        (1000.0, 0.5, 1e3, np.sqrt(0.5)),  # Hertz edge of the final contact
        (100.0, 1.0, 1e3, 0.0),  # just touches: the pressure spot shrinks onto the axis
        (100.0, 1.0005, 1e3, 0.0),  # stops 5e-4 short: spot ≈ 0.03 wide, still refined
        (100.0, 1.11, 1e3, None),  # no contact, gap 0.11: nothing thin to resolve
        (1e6, 0.05, 1e6, None),  # neck ~1e-7 thick: beyond any refined cell, not refined
    ],
)
def test_auto_refinement_follows_the_contact_the_run_ends_in(beta, z0, t_end, expected):
    rim = _contact_refinement(lubjax.Settings(), RAMP, z0, beta, t_end)
    if expected is None:
        assert rim is None
    else:
        assert rim == pytest.approx(expected)
    assert _contact_refinement(lubjax.Settings(contact_radius=None), RAMP, z0, beta, t_end) is None


def test_the_contact_interior_is_refined_only_as_far_as_the_trapped_film_needs():
    """Not for the default t̄ ≤ 5 run (its dimple is ~0.01 thick: the plain spacing leaves h̄(0)
    0.1 % off, benchmarks/accuracy.py's reference), fully (×3) for a hold to t̄ = 10³ at β = 10³
    (h̄_min ~ 3e-4), in between for β = 100; growing with β t̄ and with a tighter tolerance."""
    default = lubjax.Settings()
    assert _interior_refinement(default, 100.0, 5.0) == 1.0
    assert _interior_refinement(default, 1000.0, 1e3) == default.contact_refinement
    middle = _interior_refinement(default, 100.0, 1e3)
    assert 1.0 < middle < default.contact_refinement
    assert _interior_refinement(lubjax.Settings(rtol=3e-5), 100.0, 1e3) > middle
    assert _interior_refinement(default, 100.0, 1e2) < middle
    short = lubjax.relax(100.0, 0.5, 5.0, settings=lubjax.Settings(error_estimate=False))
    rim = _rim_refinement(default, 100.0, 5.0)
    edge_only = default.mesh(np.sqrt(0.5), 1.0, rim)
    assert lubjax.Mesh(tuple(short.r)) == edge_only.padded(short.r.size)
    assert edge_only.size < default.mesh(np.sqrt(0.5)).size


def test_the_contact_edge_is_refined_only_as_far_as_the_late_neck_needs():
    """About 5 cells across the neck (width h̄_min^{2/3}, h̄_min ≈ 0.3/√(β t̄)) at the default
    rtol: hardly any refinement for the default t̄ ≤ 5 run (its neck is ~4 plain cells wide;
    plain cells leave h̄_min 0.28 % off there, benchmarks/accuracy.py's reference), the full
    ×14 for a hold to t̄ = 10³ at β = 10³, more with a tighter tolerance; the references'
    rtol 1e-7 asks for more than their ×7 in every case."""
    default = lubjax.Settings()
    assert 1.0 <= _rim_refinement(default, 100.0, 5.0) < 1.5
    assert _rim_refinement(default, 1000.0, 1e3) == default.rim_refinement
    middle = _rim_refinement(default, 10.0, 1e3)
    assert 1.5 < middle < default.rim_refinement
    assert _rim_refinement(lubjax.Settings(rtol=1e-5), 10.0, 1e3) > middle
    tight = lubjax.Settings(rtol=1e-7, dr=0.005, rim_refinement=7.0)
    assert _rim_refinement(tight, 1.0, 1e3) == 7.0


def test_relax_refines_its_mesh_by_default():
    coarse = dict(dr=0.05, mesh_growth=1.2, length=50.0, error_estimate=False)
    auto = lubjax.relax(100.0, 0.5, 1.5, settings=lubjax.Settings(**coarse))
    plain = lubjax.relax(100.0, 0.5, 1.5, settings=lubjax.Settings(**coarse, contact_radius=None))
    assert auto.r.size > plain.r.size
    factor = _rim_refinement(lubjax.Settings(**coarse), 100.0, 1.5)  # ≈ 2.9 here
    assert factor > 2
    assert np.min(np.diff(auto.r)) == pytest.approx(0.05 / factor, rel=0.1)


def test_a_contact_slope_keeps_a_fixed_number_of_cells_across_any_contact():
    """Inside the contact the spacing is max(contact_dr, slope · r̄) (never above dr); outside
    it is the plain mesh's; a slope needs an interior spacing to start from."""
    dr, rim, slope = 0.014, 0.8, 0.028
    mesh = lubjax.graded_mesh(dr, 1.6, 100.0, 1.05, rim=rim, rim_dr=dr, contact_dr=dr / 3,
                              contact_slope=slope)
    r, cells = mesh.r, np.diff(mesh.r)
    inside = r[1:] < rim
    np.testing.assert_array_less(cells[inside], 1.02 * np.maximum(dr / 3, slope * r[1:][inside]))
    assert cells[r[1:] < dr / (3 * slope)].max() == pytest.approx(dr / 3, rel=0.02)
    assert cells[(r[:-1] > 0.5) & (r[1:] < rim)].min() > 0.9 * slope * 0.5
    assert cells[(r[:-1] > rim + 0.1) & (r[1:] <= 1.6)].max() == pytest.approx(dr, rel=0.05)
    with pytest.raises(ValueError, match="contact_slope"):
        lubjax.graded_mesh(dr, 1.6, 100.0, 1.05, rim=rim, rim_dr=dr, contact_slope=slope)


@pytest.mark.parametrize("beta", [NEAR_DRY_BETA, 1e9])
def test_near_dry_contacts_are_refined_for_the_force_not_the_film(beta):
    """From β = NEAR_DRY_BETA on ("auto"), or with film_error="force": an indenting run's mesh is
    the interior graded from the axis (dr/contact_refinement, then DRY_CONTACT_SLOPE · dr · r̄)
    and the edge refined DRY_RIM_REFINEMENT times, whatever the hold (the film's neck rule
    would refuse a hold to t̄ = 10⁶ at β = 10⁶). Below it, and with film_error="relative", the
    film's rule."""
    default = lubjax.Settings()
    dr = default.mesh_parameters()[0]
    dry = default.mesh(np.sqrt(0.5), default.contact_refinement, DRY_RIM_REFINEMENT,
                       contact_slope=DRY_CONTACT_SLOPE * dr)
    dry = dry.padded(padded_size(dry.size, default.mesh().size))
    for settings, t_end in ((default, 5.0), (default, 1e6),
                            (lubjax.Settings(film_error="force"), 5.0)):
        assert lubjax.mesh_for(settings, drive=RAMP, beta=beta, z0=0.5, t_end=t_end) == dry
    relative = lubjax.Settings(film_error="relative")
    assert lubjax.mesh_for(relative, drive=RAMP, beta=beta, z0=0.5, t_end=5.0) != dry
    below = np.nextafter(NEAR_DRY_BETA, 0.0)
    assert lubjax.mesh_for(default, drive=RAMP, beta=below, z0=0.5, t_end=5.0) == \
        lubjax.mesh_for(relative, drive=RAMP, beta=below, z0=0.5, t_end=5.0)
    # a sphere that just touches (z̄ ≥ 0: the film carries the force) keeps the axis rule
    assert lubjax.mesh_for(default, drive=RAMP, beta=beta, z0=1.0, t_end=5.0) == \
        lubjax.mesh_for(relative, drive=RAMP, beta=beta, z0=1.0, t_end=5.0)


def test_a_differentiated_near_dry_run_gets_the_whole_mesh_finer():
    """Near dry, mesh_for(derivatives=True) is the near-dry mesh of a Δr̄ DRY_DERIVATIVE_
    REFINEMENT times finer (the derivatives' spikes where the trapped film's neck crosses a
    node, docs/accuracy.md#derivatives); below NEAR_DRY_BETA, or with a given Settings.dr, the
    plain run's mesh."""
    default = lubjax.Settings()
    dr = default.mesh_parameters()[0]
    finer = lubjax.Settings(dr=dr / DRY_DERIVATIVE_REFINEMENT)
    scene = dict(drive=RAMP, z0=0.5, t_end=5.0)
    derived = lubjax.mesh_for(default, beta=1e9, derivatives=True, **scene)
    refined = lubjax.mesh_for(finer, beta=1e9, padded=False, **scene)
    assert derived == refined.padded(padded_size(refined.size, default.mesh().size))
    assert derived.size > lubjax.mesh_for(default, beta=1e9, **scene).size
    below = np.nextafter(NEAR_DRY_BETA, 0.0)
    assert lubjax.mesh_for(default, beta=below, derivatives=True, **scene) == \
        lubjax.mesh_for(default, beta=below, **scene)
    given = lubjax.Settings(dr=0.02)
    assert lubjax.mesh_for(given, beta=1e9, derivatives=True, **scene) == \
        lubjax.mesh_for(given, beta=1e9, **scene)


def test_a_padded_mesh_halves_its_far_field_cells_but_the_last():
    mesh = lubjax.graded_mesh(0.05, 1.6, 50.0, 1.2)
    padded = mesh.padded(mesh.size + 3)
    assert padded.size == mesh.size + 3 and set(mesh.nodes) <= set(padded.nodes)
    added = sorted(set(padded.nodes) - set(mesh.nodes))
    np.testing.assert_allclose(added, 0.5 * (mesh.r[-5:-2] + mesh.r[-4:-1]), rtol=1e-15)
    assert mesh.padded(mesh.size) == mesh
    with pytest.raises(ValueError, match="padded size"):
        mesh.padded(mesh.size - 1)


def test_relax_meshes_over_a_family_come_in_a_few_sizes():
    """A refined mesh is padded to ⌈N₀·2^(k/8)⌉ nodes, N₀ the plain mesh's: relax's meshes over
    β = 10⁻¹…10⁹ × z̄0 = 0.1, 0.5, 2 at t̄ = 5 have 3 sizes (unpadded, the rule gives 6: 177,
    178, 187, 236, 241, 250), each of that family."""
    settings = lubjax.Settings()
    plain = settings.mesh().size
    family = {int(np.ceil(plain * 2.0 ** (k / MESH_SIZE_STEPS))) for k in range(40)}
    sizes = {lubjax.mesh_for(settings, drive=RAMP, beta=10.0**k, z0=z0, t_end=5.0).size
             for k in range(-1, 10) for z0 in (0.1, 0.5, 2.0)}
    assert sizes <= family and len(sizes) == 3


def test_a_family_of_runs_shares_one_program_and_the_padding_is_inert():
    """relax at β = 100 and 10³ (z̄0 = 0.5, t̄ = 5) refine their contact edges differently (178
    and 187 nodes before padding), and compile one program between them; padding a mesh with
    17 more nodes in its far field moves the force, read at the same times, by less than 1e-6
    of its peak (seen: 5e-8; the steps themselves move at the tolerance's level, as the error
    control sees other nodes)."""
    settings = lubjax.Settings(error_estimate=False)
    first = lubjax.relax(100.0, 0.5, 5.0, settings=settings)
    second = lubjax.relax(1000.0, 0.5, 5.0, settings=settings)
    assert first.r.size == second.r.size and second.compile_s == 0.0
    padded = lubjax.Mesh(tuple(second.r)).padded(second.r.size + 17)
    more = lubjax.relax(1000.0, 0.5, 5.0, settings=settings, mesh=padded)
    times = np.linspace(0.01, 5.0, 300)
    moved = np.max(np.abs(more.at(times) - second.at(times)))
    assert moved < 1e-6 * np.max(np.abs(second.force))

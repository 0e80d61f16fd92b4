"""Observed order of accuracy in space under refinement (slopes fitted to successive
differences). The order in time, through the tolerance, is in test_stepper.py."""

import numpy as np
import pytest

import lubjax

BETA, Z0, T_END = 10.0, 1.0, 0.8  # smooth loading phase, before the kink at t̄ = 1


def _observed_order(values, ratio=2.0):
    """Order from successive differences of a sequence refined by ``ratio`` each time."""
    d = np.abs(np.diff(values))
    slope = np.polyfit(np.arange(d.size), np.log(d), 1)[0]
    return -slope / np.log(ratio)


@pytest.mark.slow
def test_space_order_is_two():
    """Conservative finite volumes with hat-function pressure: second order on smooth solutions
    (z̄ stays ≥ 0.2 here, so there is no contact edge to spoil it). Time error negligible:
    at rtol = 1e-8 the successive differences agree with rtol = 1e-9's to 3e-4 of themselves
    (order 2.1123 against 2.1125), for half the steps."""
    values = []
    for k in range(4):
        dr = 0.08 / 2**k
        s = lubjax.Settings(rtol=1e-8, dr=dr, r_fine=1.6, length=30.0, mesh_growth=1 + 0.16 / 2**k,
                            error_estimate=False, max_steps=100_000)
        values.append(lubjax.relax(BETA, Z0, T_END, settings=s).force[-1])
    assert 1.7 < _observed_order(values) < 2.4


def test_nested_coarse_mesh_keeps_every_other_node():
    mesh = lubjax.Settings().mesh()
    coarse = mesh.coarsened()
    assert coarse.r[-1] == mesh.r[-1] and set(coarse.nodes) <= set(mesh.nodes)
    assert coarse.size == (mesh.size + 1) // 2


@pytest.mark.slow
def test_contact_edge_refinement_resolves_the_late_neck():
    """In a long hold with z̄0 < 1 the film drains through a neck at the Hertz edge, ~h̄_min^{2/3}
    wide. Against a run refined everywhere (dr = 0.007, and dr/7 at the edge, rtol 1e-5), the
    default mesh (refined at the edge: contact_radius="auto") gets h̄_min right to 1 %; the
    unrefined mesh (contact_radius=None) is 14 % off at t̄ = 100."""
    times = [30.0, 100.0]
    fine = lubjax.Settings(rtol=1e-5, dr=0.007, length=200.0, mesh_growth=1.03,
                           error_estimate=False)  # fmt: skip
    ref = lubjax.relax(1000.0, 0.5, 100.0, settings=fine).at(times, "film_min")
    auto = lubjax.relax(1000.0, 0.5, 100.0, settings=lubjax.Settings(error_estimate=False))
    bare_settings = lubjax.Settings(error_estimate=False, contact_radius=None)
    bare = lubjax.relax(1000.0, 0.5, 100.0, settings=bare_settings)
    assert auto.r.size > bare.r.size
    err_auto = np.max(np.abs(auto.at(times, "film_min") / ref - 1))
    err_bare = np.max(np.abs(bare.at(times, "film_min") / ref - 1))
    assert err_auto < 0.01
    assert err_bare > 5 * err_auto
    # z̄0 ≥ 1 with a clear gap ends without a contact edge: the mesh is not refined.
    plain = lubjax.relax(10.0, 1.5, 1.0, settings=lubjax.Settings(error_estimate=False))
    assert plain.r.size == bare.r.size

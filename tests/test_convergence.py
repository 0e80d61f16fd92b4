"""Observed orders of accuracy under refinement (slopes fitted to successive differences)."""

import jax
import numpy as np

import lubjax

BETA, Z0, T_END = 10.0, 1.0, 0.8  # smooth loading phase, before the kink at t̄ = 1


def _force_at_end(mesh, n_steps, order):
    t = np.linspace(0.0, T_END, n_steps + 1)
    disc = lubjax.discretise(mesh)
    run = jax.jit(lambda tr, c: lubjax.rollout(disc, BETA, Z0, tr, c).force[-1])
    return float(run(lubjax.RampHold().travel(t), lubjax.bdf_coefficients(t, order)))


def _observed_order(values, ratio=2.0):
    """Order from successive differences of a sequence refined by ``ratio`` each time."""
    d = np.abs(np.diff(values))
    slope = np.polyfit(np.arange(d.size), np.log(d), 1)[0]
    return -slope / np.log(ratio)


def test_time_order_bdf2_is_two_and_backward_euler_one():
    mesh = lubjax.graded_mesh(dr=0.05, r_fine=1.6, length=30.0, growth=1.1)
    steps = [20, 40, 80, 160, 320]
    be = [_force_at_end(mesh, n, 1) for n in steps]
    bdf2 = [_force_at_end(mesh, n, 2) for n in steps]
    assert 0.85 < _observed_order(be) < 1.2
    assert 1.8 < _observed_order(bdf2) < 2.3
    # And BDF2 is the more accurate at equal cost.
    assert abs(bdf2[-1] - bdf2[-2]) < 0.1 * abs(be[-1] - be[-2])


def test_space_order_is_two():
    """Conservative finite volumes with hat-function pressure: second order on smooth solutions
    (z̄ stays ≥ 0.2 here, so there is no contact edge to spoil it)."""
    values = []
    for k in range(4):
        dr = 0.08 / 2**k
        mesh = lubjax.graded_mesh(dr=dr, r_fine=1.6, length=30.0, growth=1 + 0.16 / 2**k)
        values.append(_force_at_end(mesh, 400, 2))
    assert 1.7 < _observed_order(values) < 2.4

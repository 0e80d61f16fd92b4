"""The multistep formulae on their own, against polynomials: BDF weights, Milne's estimate, the
predictor and the dense output (lubjax/_multistep.py), and the history's push."""

import jax.numpy as jnp
import numpy as np
import pytest

from lubjax import _multistep as ms
from lubjax._stepper import Level, history_depths, push, start_history

# Variable steps: Δt, Δt₁, Δt₂, Δt₃ (ratios 0.5-2, as the controller allows)
STEPS = [(0.3, 0.2, 0.45, 0.25), (0.1, 0.15, 0.1, 0.2), (1.0, 1.0, 1.0, 1.0)]
T_N = 2.0


def _levels(dt, dt1, dt2, dt3):
    """t_{n+1}, t_n, t_{n-1}, t_{n-2}, t_{n-3}."""
    return np.array([T_N + dt, T_N, T_N - dt1, T_N - dt1 - dt2, T_N - dt1 - dt2 - dt3])


def _weights(order, dt, dt1, dt2):
    if order == 3:
        return ms.bdf3_weights(dt, dt1, dt2)
    omega = dt / dt1 if order == 2 else 0.0
    return (*ms.bdf12_weights(order, omega), 0.0)


def _lagrange_derivative_weights(nodes, x):
    """ℓ_j'(x) of the Lagrange basis on ``nodes``, computed independently (numpy polyfit)."""
    out = []
    for j in range(len(nodes)):
        basis = np.zeros(len(nodes))
        basis[j] = 1.0
        coef = np.polyfit(nodes, basis, len(nodes) - 1)
        out.append(np.polyval(np.polyder(coef), x))
    return np.array(out)


@pytest.mark.parametrize("steps", STEPS)
@pytest.mark.parametrize("order", [1, 2, 3])
def test_bdf_weights_are_the_lagrange_derivative(order, steps):
    """a_j = Δt ℓ_j'(t_{n+1}) on the levels t_{n+1}..t_{n+1-k} (the closed forms against an
    independent construction), and Σ a_j = 0."""
    dt, dt1, dt2, _ = steps
    t = _levels(*steps)[: order + 1]
    expected = dt * _lagrange_derivative_weights(t, t[0])
    got = np.array([float(a) for a in _weights(order, dt, dt1, dt2)][: order + 1])
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)
    assert abs(sum(got)) < 1e-12


@pytest.mark.parametrize("steps", STEPS)
@pytest.mark.parametrize("order", [1, 2, 3])
def test_bdf_k_is_exact_on_degree_k_and_not_k_plus_1(order, steps):
    """Σ a_j y(t_{n+1-j}) = Δt y'(t_{n+1}) for every polynomial of degree ≤ k, not for k + 1."""
    dt, dt1, dt2, _ = steps
    t = _levels(*steps)[: order + 1]
    a = np.array([float(x) for x in _weights(order, dt, dt1, dt2)][: order + 1])
    for power in range(order + 2):
        residual = a @ t**power - dt * power * t[0] ** max(power - 1, 0)
        if power <= order:
            assert abs(residual) < 1e-11, (power, residual)
        else:
            assert abs(residual) > 1e-4, (power, residual)


@pytest.mark.parametrize("steps", STEPS)
@pytest.mark.parametrize("order", [1, 2, 3])
def test_predictor_is_exact_to_its_degree(order, steps):
    dt, dt1, dt2, dt3 = steps
    t = _levels(*steps)
    for power, exact in [(order, True), (order + 1, False)]:
        y = t**power
        got = float(ms.predict(order, dt, dt1, dt2, y[1], y[2], y[3], (dt3, y[4])))
        assert (abs(got - y[0]) < 1e-11) == exact, (power, got, y[0])


@pytest.mark.parametrize("steps", STEPS)
@pytest.mark.parametrize("order", [1, 2, 3])
def test_milne_estimate_is_the_local_error_on_degree_k_plus_1(order, steps):
    """For y = t^{k+1} the corrector's local error (the BDF solution from exact history with
    the exact derivative, against the exact value) is C_c y^{(k+1)}, the predictor's C_p
    y^{(k+1)}: Milne's factor × (corrector - predictor) must equal the true local error. A
    direct computation of the constant, not of the formula."""
    dt, dt1, dt2, dt3 = steps
    t = _levels(*steps)
    power = order + 1
    y, dy = t**power, power * t[0] ** (power - 1)
    a = [float(x) for x in _weights(order, dt, dt1, dt2)]
    corrector = (dt * dy - sum(a[j] * y[j] for j in range(1, order + 1))) / a[0]
    predictor = float(ms.predict(order, dt, dt1, dt2, y[1], y[2], y[3], (dt3, y[4])))
    factor = float(ms.milne_factor(order, dt, dt1, dt2, a[0], a[1], a[2], (dt3, a[3])))
    true_error = y[0] - corrector
    assert abs(true_error) > 1e-6
    np.testing.assert_allclose(factor * (corrector - predictor), true_error, rtol=1e-9)


def test_milne_factor_is_the_classical_one_at_constant_steps():
    """Constant BDF2 steps: C_c/(C_p - C_c) = -2/11."""
    a = ms.bdf12_weights(2, 1.0)
    assert float(ms.milne_factor(2, 1.0, 1.0, 1.0, *a)) == pytest.approx(-2.0 / 11.0)


@pytest.mark.parametrize("degree, levels", [(1, 3), (2, 3), (1, 4), (2, 4), (3, 4)])
def test_dense_output_reproduces_polynomials_of_its_degree(degree, levels):
    """The dense output of a step of order p is the polynomial of degree p through the step's
    levels: exact for polynomials of that degree, not of the next; with four levels given
    (a run that may take BDF3 steps) or three (one that cannot: degree 3 needs four)."""
    times = (0.1, 0.35, 0.5, 0.9)[-levels:]
    query = np.linspace(0.5, 0.9, 7)
    for power, exact in [(degree, True), (degree + 1, False)]:
        values = tuple(t**power for t in times)
        got = np.asarray(ms.dense_output(query, times, values, degree, np))
        assert np.allclose(got, query**power, rtol=1e-13, atol=1e-15) == exact, (power, got)


def test_lagrange_through_points():
    offsets = (0.0, 0.5, 1.25)
    values = tuple((-s) ** 2 - 3 * (-s) + 1 for s in offsets)
    assert ms.lagrange(0.7, offsets, values) == pytest.approx(0.7**2 - 3 * 0.7 + 1)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_history_push_shifts_every_field_by_one_level(order):
    depths = history_depths(order)
    n = 5
    rest = Level(dt=jnp.asarray(1.0), pressure=jnp.zeros(n), elastic_load=jnp.zeros(n),
                 memory=jnp.zeros((2, n)), film=jnp.ones(n), gap=jnp.asarray(0.5),
                 gap_step=jnp.asarray(0.0), velocity=jnp.asarray(-1.0), force=jnp.asarray(0.0))
    history = start_history(rest, order)
    for field, depth in zip(Level._fields, depths):
        assert getattr(history, field).shape[0] == depth, field
    levels = [Level(*(x + k + 1 for x in rest)) for k in range(4)]
    for level in levels:
        history = push(history, level)
    for field, depth in zip(Level._fields, depths):
        stack = np.asarray(getattr(history, field))
        for j in range(depth):  # newest first
            np.testing.assert_array_equal(stack[j], np.asarray(getattr(levels[-1 - j], field)))
    # BDF3 reads one level more of everything it extrapolates or sums over
    assert history_depths(3).film == history_depths(2).film + 1
    assert history_depths(1) == history_depths(2)


def test_saver_shifts_entries_and_reads_profiles_by_the_steps_dense_output():
    """The saver (lubjax/_output.py) on its own: on an accepted step t → t_new a profile time
    inside (t, t_new] gets the step's interpolant of p̄, z̄ and h̄ (here exact: quadratic data, a
    BDF2 step); one outside keeps what it had."""
    from lubjax._output import Profiles, save_profiles
    from lubjax._stepper import Candidate, Estimate

    n, t = 3, 1.0  # levels at t = 0.5, 0.8, 1.0; the new one at 1.25
    t_new = 1.25

    def q(s):  # quadratic in time, one value per node
        return jnp.asarray([s**2, 2 * s**2 - s, 1.0 + s])

    rest = Level(dt=jnp.asarray(1.0), pressure=jnp.zeros(n), elastic_load=jnp.zeros(n),
                 memory=jnp.zeros((0, n)), film=jnp.ones(n), gap=jnp.asarray(0.0),
                 gap_step=jnp.asarray(0.0), velocity=jnp.asarray(0.0), force=jnp.asarray(0.0))
    history = start_history(rest, 2)
    for time_, dt in ((0.5, 1.0), (0.8, 0.3), (1.0, 0.2)):
        history = push(history, rest._replace(dt=jnp.asarray(dt), pressure=q(time_),
                                              film=q(time_) + 1, gap=jnp.asarray(time_ ** 2)))
    new = rest._replace(dt=jnp.asarray(t_new - t), pressure=q(t_new), film=q(t_new) + 1,
                        gap=jnp.asarray(t_new**2))
    candidate = Candidate(new, Estimate(*(jnp.zeros(()),) * 4), jnp.asarray(2), 0.0, 0.0)
    times = jnp.asarray([0.9, 1.1, 1.25, 1.3])
    before = Profiles(jnp.full((4, n), -1.0), jnp.full(4, -1.0), jnp.full((4, n), -1.0))
    after = save_profiles(before, jnp.asarray(t), jnp.asarray(t_new), history, candidate, times)
    for j, s in enumerate(np.asarray(times)):
        inside = t < s <= t_new
        expect_p = np.asarray(q(s)) if inside else np.full(n, -1.0)
        np.testing.assert_allclose(np.asarray(after.pressure[j]), expect_p, rtol=1e-13)
        np.testing.assert_allclose(float(after.gap[j]), s**2 if inside else -1.0, rtol=1e-13)
        np.testing.assert_allclose(np.asarray(after.film[j]),
                                   expect_p + 1 if inside else np.full(n, -1.0), rtol=1e-13)

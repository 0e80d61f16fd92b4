r"""One linearly implicit step (paper Section 5, eqs 17-22): the candidate level and its error.

Every attempted step is the paper's *one* linear system, factorised once: the mobility is taken
from known levels (eq 19), so the step is linear in p̄ⁿ⁺¹; a second back-substitution with the
same factors corrects the mobility. :func:`step` returns the candidate level, Milne's estimates
of its local error and what the dense output needs; whether it is kept, and the next Δt̄, is
the controller's (:mod:`lubjax._controller`), the loop the rollout's (:mod:`lubjax._loop`).

Departures from the paper, and why:

* Time derivative by variable-step BDF2 (the paper's backward Euler, BDF1, starts every segment
  and steps a force tail decayed below its absolute tolerance, where BDF2 would oscillate).
  For BDF2 the mobility film is extrapolated *geometrically*, h̄* = h̄ⁿ (h̄ⁿ/h̄ⁿ⁻¹)^ω with
  ω = Δt̄ₙ/Δt̄ₙ₋₁: second-order like linear extrapolation, but positive whenever the film is.
* ``Settings(order=3)``: variable-step BDF3 from a segment's fourth step on (an option; BDF2 is
  the default), the same one factorisation and two triangular solves per attempt, with the
  mobility film extrapolated quadratically in ln h̄ (third-order, positive) and Milne's
  estimate paired with the cubic predictor. At tight tolerances it needs half to two thirds of
  BDF2's steps, for every drive and substrate; its error is smaller where the time error
  dominates, the mesh's where that dominates (tests/test_stepper.py;
  benchmarks/work_precision.py charts it).
* Mobility corrected in a second stage on the same LU factors (like a two-stage Rosenbrock-W
  step: one factorisation, two triangular solves): with the film h̄ⁿ⁺¹ of the first stage, one
  simplified-Newton correction M δ = (T(g(h̄ⁿ⁺¹)) - T(g(h̄*))) p̄ⁿ⁺¹ replaces the extrapolated
  conductances by those of the new film. Why: where the film is nearly rigid (z̄0 > 1) the
  pressure is algebraic in the film, so the O(Δt̄²) error of the extrapolated h̄* is an error
  of p̄ and F̄ at every step, smooth from step to step, which Milne's estimate cannot see:
  uncorrected, the force at β = 100, z̄0 = 2, rtol 1e-3 is 3.4e-3 of its peak off; corrected,
  5.7e-4 on the same steps (benchmarks/studies/time_error.py), and long holds need fewer steps
  (β = 100, z̄0 = 0.5 to t̄ = 10⁶: 1783 instead of 3148). The cost is O(N²) per attempt
  against the O(N³) factorisation. The film volume still changes exactly by the reported
  outer flux (the two stages' fluxes; tests/test_analytic_limits.py).
* Adaptive steps: the difference between the BDF solution and the extrapolation of the
  accepted history estimates the local error (Milne's device, :mod:`lubjax._multistep`); a
  step is rejected and retried shorter when that error exceeds the tolerance *or* when the film
  would lose positivity (the paper's scheme drives it negative, docs/model.md). No separate
  safeguard.
* Since h̄ⁿ = z̄ⁿ + r̄²/2 + Ŵp̄ⁿ, the unknown is p̄ⁿ⁺¹ alone: one (N-1)×(N-1) dense factorisation
  per attempt with Ŵ precomputed (the paper solves the 2N×2N system in p̄ and w̄).

The history is one pytree (:class:`Level` stacked on a leading axis of levels, newest first);
each field keeps the levels the formulae of the highest order a run may use read
(:func:`history_depths`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import _multistep as ms
from ._discretisation import (
    FILM_STENCIL,
    Discretisation,
    conductance_of_extrapolated,
    face_conductance,
    face_conductance_extrapolated,
    film_at_midpoints,
    film_thickness,
    flux_divergence,
)


class Level(NamedTuple):
    """One accepted level tⁿ of a run. Stacked on a leading axis of levels [n, n-1, ...] it is
    the run's history (:func:`history_depths` says how many levels each field keeps)."""

    dt: jax.Array  # tⁿ - tⁿ⁻¹
    pressure: jax.Array  # p̄ⁿ (N,)
    elastic_load: jax.Array  # ūⁿ: w̄ = -Ŵū (= p̄ on an elastic substrate; _substrate)
    memory: jax.Array  # internal variables q_kⁿ of a viscoelastic substrate (K, N)
    film: jax.Array  # h̄ⁿ (N,)
    gap: jax.Array  # z̄ⁿ
    gap_step: jax.Array  # Δz̄ⁿ = z̄ⁿ - z̄ⁿ⁻¹ as solved (the difference of gaps rounds it)
    velocity: jax.Array  # dz̄/dt̄ at level n by the step's BDF formula (a free sphere's state)
    force: jax.Array  # F̄ⁿ


class History(NamedTuple("Levels", [(name, jax.Array) for name in Level._fields])):
    """The accepted levels a step reads, newest first: every field of :class:`Level` with a
    leading axis of levels (:func:`history_depths` of them)."""

    __slots__ = ()

    def newest(self) -> Level:
        """The newest level, n."""
        return Level(*(x[0] for x in self))


def history_depths(max_order: int) -> Level:
    """Levels each field keeps: what BDF-q (q = max(order, 2)) reads. Its derivative reads q
    levels of the known loads and q - 1 gap steps; the predictor (Milne's estimate) q + 1 levels
    of the controlled quantities; the dense output q levels of the profiles besides the new one;
    Δt̄ of q levels."""
    q = max(max_order, 2)
    return Level(dt=q, pressure=q, elastic_load=q, memory=q, film=q + 1, gap=q + 1,
                 gap_step=q - 1, velocity=q + 1, force=q + 1)


def start_history(level: Level, max_order: int) -> History:
    """A history whose every level is ``level`` (a run at rest)."""
    return History(*(jnp.broadcast_to(x, (depth, *jnp.shape(x)))
                     for x, depth in zip(level, history_depths(max_order), strict=True)))


def push(history: History, level: Level) -> History:
    """The history with ``level`` as its newest level (the oldest falls off)."""
    return History(*(jnp.concatenate([x[None].astype(stack.dtype), stack[:-1]])
                     for stack, x in zip(history, level, strict=True)))


class StepRecord(NamedTuple):
    """What a drive's row and a substrate's loads see of a step tⁿ → tⁿ⁺¹."""

    t: jax.Array
    t_new: jax.Array
    dt: jax.Array
    weights: tuple  # BDF weights (a₀, a₁, a₂, a₃); a₃ None where no step can be BDF3
    history: History


class Estimate(NamedTuple):
    """Milne's estimates of the candidate's local error (:mod:`lubjax._multistep`)."""

    film: jax.Array  # at every node (N,)
    force: jax.Array
    gap: jax.Array  # zero where the drive prescribes the gap
    velocity: jax.Array  # zero unless the drive has inertia


class Candidate(NamedTuple):
    """What :func:`step` returns: the new level, its error estimate, its formula's order (also
    the degree of its dense output) and the step's diagnostics."""

    level: Level
    estimate: Estimate
    order: jax.Array
    outflow: jax.Array  # volume flux out through the last face over the step, per unit 2π
    dissipation: jax.Array  # viscous power D̄ = 2π Σ_faces g (Δp̄)²


def linear_step(
    disc: Discretisation, beta, conductance, dt, a0, gap_history_rate, compliance, known_load,
    row,
):
    """One step: solve for (p̄ⁿ⁺¹, Δz̄), Δz̄ = z̄ⁿ⁺¹ - z̄ⁿ, from the N-1 Reynolds rows

        A (a₀Δz̄ - a₂Δz̄ⁿ + Ŵ(a₀ c p̄ⁿ⁺¹ + known_load))/Δt = T p̄ⁿ⁺¹

    (the BDF form of (R) in :mod:`lubjax._drives`, a₁ = -(a₀ + a₂), so a₀z̄ⁿ⁺¹ + a₁z̄ⁿ + a₂z̄ⁿ⁻¹
    = a₀Δz̄ - a₂Δz̄ⁿ, with the elastic load ūⁿ⁺¹ = c p̄ⁿ⁺¹ + ... of :mod:`lubjax._substrate`)
    and the drive's row α c·p̄ⁿ⁺¹ + s Δz̄ = b, ``row = (α, s, b)``.

    ``gap_history_rate`` = -a₂Δz̄ⁿ; ``compliance`` = c (1 on an elastic substrate) and
    ``known_load`` = a₀ūⁿ⁺¹ - a₀c p̄ⁿ⁺¹ + a₁ūⁿ + a₂ūⁿ⁻¹ (= a₁p̄ⁿ + a₂p̄ⁿ⁻¹ if elastic). The r̄²/2
    terms of h̄ cancel exactly (Σa = 0), so the right-hand side holds only differences of the
    gap and the elastic part: no O(1) film values cancel, and a decaying pressure (F̄ → 10⁻¹⁰⁰
    in a long hold at z̄0 > 1) keeps its relative accuracy and its sign. The flux operator T is
    tridiagonal with face conductances g_{i+1/2} = β · ``conductance`` (:func:`face_conductance`):
    (Tp̄)_i = g_{i+1/2}(p̄_{i+1} - p̄_i) - g_{i-1/2}(p̄_i - p̄_{i-1}).
    Unknowns p̄_0..p̄_{N-2} (p̄_{N-1} = 0, eq 22b) and Δz̄: one N×N dense LU factorisation.
    With a prescribed travel the row is (0, 1, b): partial pivoting never picks it before the
    last column, so Δz̄ = b exactly. Returns (p̄ⁿ⁺¹, Δz̄, conductances g, solve), ``solve`` the
    system's inverse on the same factors (:func:`_factorised`) for the mobility's second stage.
    """
    g = beta * conductance
    matrix, rhs = _linear_system(disc, g, dt, a0, gap_history_rate, compliance, known_load, row)
    solve = _factorised(matrix)
    x = solve(rhs)
    p = jnp.concatenate([x[:-1], jnp.zeros(1, x.dtype)])
    return p, x[-1], g, solve


def _linear_system(disc: Discretisation, g, dt, a0, gap_history_rate, compliance, known_load,
                   row):
    """The matrix and right-hand side of :func:`linear_step`'s system for face conductances
    ``g`` (β included)."""
    n = disc.r.shape[0] - 1
    idx = jnp.arange(n)
    off = jnp.arange(n - 1)
    diag = g[:n] + jnp.concatenate([jnp.zeros(1, g.dtype), g[: n - 1]])
    # (compliance None: an elastic substrate, c = 1, and the arithmetic of the elastic step)
    scale = a0 / dt if compliance is None else a0 * compliance / dt
    block = scale * disc.area_influence
    block = block.at[idx, idx].add(diag)
    block = block.at[off, off + 1].add(-g[: n - 1]).at[off + 1, off].add(-g[: n - 1])
    area = disc.cell_area[:-1]
    alpha, s, b = row
    dtype = block.dtype
    matrix = jnp.concatenate(
        [
            jnp.concatenate([block, ((a0 / dt) * area)[:, None]], axis=1),
            jnp.concatenate(
                [alpha * disc.force_weights[None, :-1], jnp.reshape(s, (1, 1))], axis=1
            ).astype(dtype),
        ],
        axis=0,
    )
    rate = gap_history_rate + disc.influence @ known_load
    rhs = jnp.concatenate([-(area * rate[:-1] / dt), jnp.reshape(b, (1,)).astype(dtype)])
    return matrix, rhs


def _factorised(matrix):
    """x ↦ matrix⁻¹x by one LU factorisation, reusable for several right-hand sides, and
    differentiated as ``jnp.linalg.solve`` is (custom_linear_solve: tangents and cotangents reuse
    the factors; the factorisation itself is not differentiated)."""
    lu, pivots, _ = jax.lax.linalg.lu(jax.lax.stop_gradient(matrix))

    def solve(b):
        return jax.lax.custom_linear_solve(
            lambda x: matrix @ x,
            b,
            solve=lambda _, v: jax.scipy.linalg.lu_solve((lu, pivots), v, trans=0),
            transpose_solve=lambda _, v: jax.scipy.linalg.lu_solve((lu, pivots), v, trans=1),
        )

    return solve


def _weights_and_conductance(disc, history: History, dt, order, max_order):
    """The step's BDF weights (a₀, a₁, a₂, a₃) and the conductances of its mobility film:
    backward Euler lags the film (eq 19); BDF2 extrapolates it geometrically; BDF3 quadratically
    in ln h̄ through three levels (third-order and positive like the geometric one; where a level
    is not positive, the last film)."""
    dt1, dt2 = history.dt[0], history.dt[1]
    low = jnp.minimum(order, 2)  # BDF3 steps select their own weights and conductance below
    omega = jnp.where(low == 2, dt / dt1, 0.0)
    a0, a1, a2 = ms.bdf12_weights(low, omega)
    film, gap = history.film, history.gap
    conductance = face_conductance_extrapolated(disc, film[0], film[1], gap[0], gap[1], omega)
    if max_order < 3:
        return (a0, a1, a2, None), conductance

    def log_quadratic(h, h1, h2):
        positive = (h > 0) & (h1 > 0) & (h2 > 0)
        logs = [jnp.log(jnp.where(positive, x, 1.0)) for x in (h, h1, h2)]
        return jnp.where(positive, jnp.exp(ms.lagrange(dt, (0.0, dt1, dt1 + dt2), logs)), h)

    is3 = order == 3
    b0, b1, b2, b3 = ms.bdf3_weights(dt, dt1, dt2)
    a0, a1, a2 = (jnp.where(is3, b, a) for a, b in ((a0, b0), (a1, b1), (a2, b2)))
    levels = tuple((film[j], gap[j]) for j in range(3))
    quadratic = conductance_of_extrapolated(disc, log_quadratic, levels)
    return (a0, a1, a2, jnp.where(is3, b3, 0.0)), jnp.where(is3, quadratic, conductance)


def _solve_two_stages(disc, beta, conductance, record: StepRecord, row, loads):
    """The step's solve and the mobility's second stage on the same factors: the conductances
    of the film the first stage gives, g(h̄ⁿ⁺¹), replace the extrapolated ones g(h̄*) by one
    simplified-Newton correction M δ = (T(g(h̄ⁿ⁺¹)) - T(g(h̄*))) p̄ⁿ⁺¹. Returns p̄ⁿ⁺¹, Δz̄, the
    new conductances, the outer flux and the gap's history sum (the velocity's BDF formula needs
    it).

    Derivatives are those of the fully implicit step (:func:`_implicit`), not of these two
    stages: the values are the two stages', the tangents the implicit function theorem's."""
    history, (a0, _, a2, a3) = record.history, record.weights
    # Σ_j a_j z̄ⁿ⁺¹⁻ʲ = a₀Δz̄ + gap_history in the solved steps (Σ a_j = 0):
    # -a₂Δz̄ⁿ (BDF2), -a₂Δz̄ⁿ - a₃(Δz̄ⁿ + Δz̄ⁿ⁻¹) (BDF3)
    gap_history = -a2 * history.gap_step[0]
    if a3 is not None:
        gap_history = gap_history - a3 * (history.gap_step[0] + history.gap_step[1])
    sg = jax.lax.stop_gradient
    p, dz, g_new, outflow = _two_stages(
        disc, sg(beta), sg(conductance), sg(record.dt), sg(a0), sg(gap_history),
        sg(history.gap[0]), sg(row), sg(loads.compliance), sg(loads.known),
        lambda p: sg(loads.loads(p)[1]),
    )
    compliance = 1.0 if loads.compliance is None else loads.compliance
    system = ImplicitStep(
        disc=disc, beta=beta, dt=record.dt, a0=a0, gap_history=gap_history,
        compliance=compliance, known_load=loads.known,
        load_offset=loads.loads(jnp.zeros_like(p))[1], row=tuple(row), gap=history.gap[0],
    )
    x = _implicit(jnp.concatenate([p[:-1], jnp.reshape(dz, (1,))]), system)
    p_new = jnp.concatenate([x[:-1], jnp.zeros(1, x.dtype)])
    _, g_implicit = _implicit_film(x, system)
    g_new = _value_with_tangent_of(g_new, g_implicit)
    outflow = _value_with_tangent_of(outflow, g_implicit[-1] * p_new[-2])
    return p_new, x[-1], g_new, outflow, gap_history


def _two_stages(disc, beta, conductance, dt, a0, gap_history, gap, row, compliance, known,
                load_of):
    """The values of :func:`_solve_two_stages` (the two stages on one factorisation)."""
    p, dz, g, solve = linear_step(
        disc, beta, conductance, dt, a0, gap_history, compliance, known, row
    )
    z_first = gap + dz
    h_first = film_thickness(disc, z_first, load_of(p))
    g_new = beta * face_conductance(disc, h_first, film_at_midpoints(disc, h_first, z_first))
    residual = flux_divergence(g_new - g, p)
    delta = solve(jnp.concatenate([residual[:-1], jnp.zeros(1, p.dtype)]))
    corrected = p + jnp.concatenate([delta[:-1], jnp.zeros(1, p.dtype)])
    # The rows now hold as A Δh̄ a₀/Δt̄ = T(g*) p̄_corrected + T(g_new - g*) p̄_first, and T
    # telescopes: the film's volume changes by exactly this outer flux, the one reported.
    outflow = -g[-1] * (corrected[-1] - corrected[-2]) - (g_new[-1] - g[-1]) * (p[-1] - p[-2])
    return corrected, dz + delta[-1], g_new, outflow


class ImplicitStep(NamedTuple):
    """The fully implicit step whose solution the two stages approximate: :func:`linear_step`'s
    system with the conductances of the new film, g(h̄ⁿ⁺¹), and ūⁿ⁺¹ = c p̄ⁿ⁺¹ + ū₀."""

    disc: Discretisation
    beta: jax.Array
    dt: jax.Array
    a0: jax.Array
    gap_history: jax.Array
    compliance: jax.Array  # c
    known_load: jax.Array
    load_offset: jax.Array  # ū₀, the elastic load of p̄ⁿ⁺¹ = 0
    row: tuple  # the drive's (α, s, b)
    gap: jax.Array  # z̄ⁿ


def _implicit_film(x, system: ImplicitStep):
    """h̄ⁿ⁺¹ of the unknowns x = (p̄_0..p̄_{N-2}, Δz̄), and its face conductances g(h̄ⁿ⁺¹)
    (β included)."""
    p = jnp.concatenate([x[:-1], jnp.zeros(1, x.dtype)])
    disc = system.disc
    load = system.compliance * p + system.load_offset
    z = system.gap + x[-1]
    film = film_thickness(disc, z, load)
    return film, system.beta * face_conductance(disc, film, film_at_midpoints(disc, film, z))


def _implicit_residual(x, system: ImplicitStep):
    """The fully implicit step's residual at x = (p̄_0..p̄_{N-2}, Δz̄) (zero at its solution)."""
    _, g = _implicit_film(x, system)
    matrix, rhs = _linear_system(system.disc, g, system.dt, system.a0, system.gap_history,
                                 system.compliance, system.known_load, system.row)
    return matrix @ x - rhs


def _implicit_jacobian(x, system: ImplicitStep):
    """∂(residual)/∂x: the linear system's matrix at g(h̄ⁿ⁺¹) plus the conductances' dependence
    on the film, -β ∂(T(g(h̄))p̄)/∂h̄ · ∂h̄/∂x, with the banded ∂(T(g(h̄))p̄)/∂h̄ (node i's
    fluxes see the films of nodes i-2..i+2: a face's midpoint film takes four nodes,
    :func:`lubjax._discretisation.film_at_midpoints`) read off five jvps (nodes coloured
    i mod 5) and ∂h̄/∂p̄_j = c Ŵ_{:j}, ∂h̄/∂Δz̄ = 1."""
    disc = system.disc
    n = disc.r.shape[0]
    p = jnp.concatenate([x[:-1], jnp.zeros(1, x.dtype)])
    film, g = _implicit_film(x, system)
    z = system.gap + x[-1]

    def flux(h):
        g = system.beta * face_conductance(disc, h, film_at_midpoints(disc, h, z))
        return flux_divergence(g, p)

    width = 2 * FILM_STENCIL + 1
    colours = jnp.arange(n) % width
    columns = jnp.stack([jax.jvp(flux, (film,), ((colours == k).astype(film.dtype),))[1]
                         for k in range(width)])
    rows = jnp.arange(n)
    dh = jnp.concatenate(
        [system.compliance * disc.influence[:, :-1], jnp.ones((n, 1), film.dtype)], axis=1
    )
    coupling = jnp.zeros_like(dh)
    for offset in range(-FILM_STENCIL, FILM_STENCIL + 1):
        # ∂(flux_i)/∂h̄_{i+offset} times row i+offset of ∂h̄/∂x (zero where that node is absent)
        inside = (rows + offset >= 0) & (rows + offset < n)
        diagonal = jnp.where(inside, columns[(rows + offset) % width, rows], 0.0)
        coupling = coupling + diagonal[:, None] * jnp.roll(dh, -offset, axis=0)
    matrix, _ = _linear_system(disc, g, system.dt, system.a0, system.gap_history,
                               system.compliance, system.known_load, system.row)
    return matrix - jnp.concatenate([coupling[:-1], jnp.zeros((1, n), film.dtype)])


@jax.custom_jvp
def _implicit(x, system: ImplicitStep):
    """x, the step's unknowns, with the derivative of the fully implicit step's solution.

    Why: the two stages take the mobility h̄³ from known levels (extrapolated, then corrected
    once on frozen factors). Their values are second-order accurate, but their linearisation
    treats the film's perturbation in the mobility explicitly: a term like ∂_r(3h̄²δh̄ ∂_r p̄),
    an advection of δh̄ at a speed ∝ β h̄² |∂_r p̄| with an explicit step's stability limit. Near
    dry (β ≳ 10⁶) the steps the primal needs outgrow that limit at the contact's edge and the
    tangent grows without bound while the values stay right. The implicit function theorem on
    the fully implicit step, R(xⁿ⁺¹; history, parameters) = 0, gives the tangent of a BDF step
    that is implicit in every term, stable on any step the primal takes: one more dense LU per
    step, for the derivatives only."""
    return x


@_implicit.defjvp
def _implicit_jvp(primals, tangents):
    x, system = primals
    _, system_dot = tangents
    jacobian = jax.lax.stop_gradient(_implicit_jacobian(x, system))
    _, residual_dot = jax.jvp(lambda s: _implicit_residual(x, s), (system,), (system_dot,))
    lu, pivots, _ = jax.lax.linalg.lu(jacobian)
    x_dot = -jax.scipy.linalg.lu_solve((lu, pivots), residual_dot)
    return x, x_dot


@jax.custom_jvp
def _value_with_tangent_of(value, proxy):
    """``value``, with the tangent of ``proxy`` (the same quantity of the implicit step)."""
    return value


@_value_with_tangent_of.defjvp
def _value_with_tangent_of_jvp(primals, tangents):
    return primals[0], tangents[1]


def step(disc: Discretisation, beta, drive, substrate, history: History, t, t_new, order,
         max_order: int) -> Candidate:
    """One attempted step tⁿ = ``t`` → tⁿ⁺¹ = ``t_new`` by the formula of ``order`` (1, 2 or
    3; :func:`lubjax._controller.choose_order`) from the accepted ``history``: the candidate
    level, Milne's estimates of its local error and its diagnostics. ``max_order`` (static):
    the highest order the run uses, which fixes the history's depth and the program's branches.
    """
    dt = t_new - t
    weights, conductance = _weights_and_conductance(disc, history, dt, order, max_order)
    record = StepRecord(t, t_new, dt, weights, history)
    loads = substrate.step_loads(record)
    p, dz, g, outflow, gap_history = _solve_two_stages(
        disc, beta, conductance, record, drive.row(record), loads
    )
    memory, load = loads.loads(p)
    z_new = history.gap[0] + dz
    level = Level(
        dt=dt, pressure=p, elastic_load=load, memory=memory,
        film=film_thickness(disc, z_new, load), gap=z_new, gap_step=dz,
        velocity=(weights[0] * dz + gap_history) / dt, force=disc.force_weights @ p,
    )
    return Candidate(
        level=level,
        estimate=_estimate(level, history, order, weights, drive),
        order=order,
        outflow=outflow,
        dissipation=2.0 * jnp.pi * jnp.sum(g * (p[1:] - p[:-1]) ** 2),
    )


def _estimate(level: Level, history: History, order, weights, drive) -> Estimate:
    """Milne's estimates on the film at every node, on F̄, and on the sphere's position and
    velocity where the drive leaves them free (zero where it does not)."""
    a0, a1, a2, a3 = weights
    dt, dt1, dt2 = level.dt, history.dt[0], history.dt[1]
    bdf3 = a3 is not None
    factor = ms.milne_factor(order, dt, dt1, dt2, a0, a1, a2,
                             (history.dt[2], a3) if bdf3 else None)

    def milne(field):
        new, y = getattr(level, field), getattr(history, field)
        third = (history.dt[2], y[3]) if bdf3 else None
        return factor * (new - ms.predict(order, dt, dt1, dt2, y[0], y[1], y[2], third))

    zero = jnp.zeros_like(level.force)
    return Estimate(
        film=milne("film"),
        force=milne("force"),
        gap=zero if drive.prescribes_gap else milne("gap"),
        velocity=milne("velocity") if drive.inertia else zero,
    )

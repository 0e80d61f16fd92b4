r"""The error-controlled, linearly implicit time stepper (paper Section 5, eqs 17-22).

Reynolds (eq 8a) in conservative, finite-volume form on a (graded) mesh. Node i owns the cell
[r̄_{i-1/2}, r̄_{i+1/2}] (midpoints; r̄_{-1/2} = 0) of area measure A_i = (r̄²_{i+1/2} - r̄²_{i-1/2})/2:

    A_i dh̄_i/dt̄ = β g_{i+1/2} (p̄_{i+1} - p̄_i) - β g_{i-1/2} (p̄_i - p̄_{i-1}),

with the face conductances g ≈ r̄ h̄³/Δr̄ (:func:`face_conductance`: a harmonic Simpson mean of
r̄/h̄³ across the cell) and h̄ = z̄ + r̄²/2 + Ŵ p̄ (eq 8a with w̄ = -Ŵ p̄, eq 21).
The axis needs no special row: the face at r̄ = 0 carries no flux, which is ∂p̄/∂r̄ = 0 there
(eq 22a). The outer node carries p̄ = 0 (eq 22b) at a large L̄.

Every attempted step is still the paper's *one* linear system, factorised once: the mobility is
taken from known levels (eq 19), so the step is linear in p̄ⁿ⁺¹; a second back-substitution with
the same factors corrects the mobility (below). What changed is who chooses the step: an embedded
error estimate and a PI controller (:mod:`lubjax._controller`), not a hand-made grid.

Departures from the paper, and why:

* Conservative form instead of the expanded form (17a) with the one-sided ∂p̄/∂r̄ (17c): it is
  second-order in space on any mesh (17c is first order), and the film volume changes exactly by
  the flux through the outer face (tested).
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
  of p̄ and F̄ at every step, smooth from step to step, which Milne's estimate cannot see: at
  rtol 1e-3 the force at β = 100, z̄0 = 2 was 3.4e-3 of its peak off; corrected, 5.7e-4 on the
  same steps (benchmarks/time_error.py), and long holds need fewer steps (β = 100, z̄0 = 0.5
  to t̄ = 10⁶: 1783 instead of 3148). The cost is O(N²) per attempt against the O(N³)
  factorisation. The film volume still changes exactly by the reported outer flux (the
  two stages' fluxes; tests/test_analytic_limits.py).
* Adaptive steps: the difference between the BDF2 solution and the quadratic extrapolation of the
  accepted history estimates the local error (Milne's device); a step is rejected and retried
  shorter when that error exceeds the tolerance *or* when the film would lose positivity (the
  paper's scheme drives it negative, MODEL.md). No separate safeguard.
* Since h̄ⁿ = z̄ⁿ + r̄²/2 + Ŵp̄ⁿ, the unknown is p̄ⁿ⁺¹ alone: one (N-1)×(N-1) dense factorisation
  per attempt with Ŵ precomputed (the paper solves the 2N×2N system in p̄ and w̄).
* Velocity jumps of the indenter (``history.breakpoints``) are landed on exactly, and the
  integration restarts there with a short backward-Euler step, as at t̄ = 0: the pressure then
  adjusts on the fast time scale 1/β.

The loop over attempts is a ``lax.while_loop`` (``mode="forward"``: stops when done; jit, vmap,
jvp) or a ``lax.scan`` over a fixed budget of attempts with finished attempts masked by
``lax.cond`` and each body under ``jax.checkpoint`` (``mode="reverse"``: also vjp / ``jax.grad``,
memory ∝ budget × state, not a factorisation per step). Both run the same attempt function.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _controller as ctrl
from ._drives import as_drive
from ._influence import force_weights, influence_matrix
from ._mesh import Mesh
from ._substrate import HalfSpace, as_substrate

#: Names the spatial discretisation, for caches of computed runs (benchmarks/accuracy.py): the
#: pressure's squeeze-film-weighted hats (lubjax/_influence.py) and the radius inside the
#: conductance's mean (:func:`face_conductance`) changed results at fixed settings.
DISCRETISATION = "psi-weighted hats, radius-weighted conductance"


class Discretisation(NamedTuple):
    """Mesh-dependent arrays, computed once per mesh (a pytree of arrays: pass it to jit)."""

    r: jax.Array  # nodes (N,)
    cell_area: jax.Array  # A_i = (r²_{i+1/2} - r²_{i-1/2})/2, (N,)
    face_r: jax.Array  # r_{i+1/2}, (N-1,)
    face_gap: jax.Array  # r_{i+1} - r_i, (N-1,)
    influence: jax.Array  # Ŵ, (N, N)
    area_influence: jax.Array  # (A Ŵ)_ij restricted to the unknowns i, j < N-1
    force_weights: jax.Array  # F̄ = c·p̄, (N,)


def discretise(mesh: Mesh, substrate=None) -> Discretisation:
    """All per-mesh arrays for a substrate's geometry (default: the half-space); cached, so the
    influence matrix is built once per (mesh, elastic substrate)."""
    return _discretise(mesh, as_substrate(substrate).elastic)


@functools.lru_cache(maxsize=32)
def _discretise(mesh: Mesh, elastic) -> Discretisation:
    r = mesh.r
    face = 0.5 * (r[1:] + r[:-1])
    outer = np.concatenate([face, [r[-1]]])
    inner = np.concatenate([[0.0], face])
    area = 0.5 * (outer**2 - inner**2)
    w = influence_matrix(mesh) if isinstance(elastic, HalfSpace) else elastic.influence(mesh)
    arrays = (r, area, face, np.diff(r), w, area[:-1, None] * w[:-1, :-1], force_weights(mesh))
    # device_put, not jnp.asarray: outside jit, jnp.asarray compiles a copy per new shape
    # (~20 ms each, 0.15 s of a fresh relax call).
    return Discretisation(*(jax.device_put(np.asarray(a, np.float64)) for a in arrays))


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["rtol", "atol", "initial_step", "force_floor"],
    meta_fields=["order", "max_steps"],
)
@dataclasses.dataclass(frozen=True)
class Tolerance:
    """What the controller needs. A pytree: the numbers (rtol, atol, initial_step,
    force_floor) are leaves, so a tolerance passed to ``jit`` as an argument is traced and one
    compiled program serves every tolerance; ``order`` and ``max_steps`` shape the program and
    are static. Closed over (as ``sweep`` and the fits do), it is a constant of the program.

    rtol, atol: the step's estimated local error e (film h̄ at every node, and F̄) must satisfy
        |e| ≤ atol + rtol·|value|; a free gap z̄, |e| ≤ atol + rtol·max|z̄ - z̄_start|.
        initial_step: the first step after t̄_start and after each velocity jump, divided by
        max(1, β). order: 2 (BDF2), 1 (backward Euler throughout) or 3 (BDF3 from a segment's
        fourth step). max_steps: the attempt
        budget (accepted + rejected). force_floor: F̄ is held to rtol relative to max(|F̄|,
        force_floor × its peak so far).
    """

    rtol: float = 1e-4
    atol: float = 1e-9
    initial_step: float = 1e-5
    order: int = 2
    max_steps: int = 20_000
    force_floor: float = 1e-8


DEFAULT_TOLERANCE = Tolerance()
# The force's absolute floor: above its rounding in the solve (~4e-14, where a smooth start makes
# it emerge from zero) and below 1e-6 of the smallest peak force of the mapped range (~1.5e-3 at
# β = 10³, z̄0 = 2). The film's floor is Settings.atol (1e-9): a relative control of the thinnest
# necks (h̄ ~ 1e-7 at β = 10⁶) stalled on their rounding on coarse meshes.
FORCE_ATOL = 1e-12
#: Below this |F̄| (10 × its absolute tolerance) steps are backward Euler (_attempt).
BACKWARD_EULER_FORCE = 10.0 * FORCE_ATOL
#: How much the force's tolerance tightens per decade a tail has decayed below its peak (_attempt).
TAIL_TIGHTENING = 3.0

# Status codes of a run.
RUNNING, DONE, STEP_TOO_SMALL = 0, 1, 2


class State(NamedTuple):
    """Stepper state at the last accepted level t_n, with the history BDF2 and the error estimate
    need (levels n-1, n-2), and the controller's memory. A pytree."""

    t: jax.Array
    dt_prev: jax.Array  # t_n - t_{n-1}
    dt_prev2: jax.Array  # t_{n-1} - t_{n-2}
    dt_prev3: jax.Array  # t_{n-2} - t_{n-3} (BDF3)
    pressure: jax.Array  # p̄ⁿ (N,)
    pressure_prev: jax.Array  # p̄ⁿ⁻¹ (N,)
    pressure_prev2: jax.Array  # p̄ⁿ⁻² (N,): BDF3's interpolant
    elastic_load: jax.Array  # ūⁿ: w̄ = -Ŵū (= p̄ on an elastic substrate; _substrate)
    elastic_load_prev: jax.Array
    elastic_load_prev2: jax.Array  # (BDF3)
    memory: jax.Array  # internal variables q_kⁿ of a viscoelastic substrate (K, N)
    memory_prev: jax.Array
    memory_prev2: jax.Array  # (BDF3)
    film: jax.Array  # h̄ⁿ (N,)
    film_prev: jax.Array
    film_prev2: jax.Array
    film_prev3: jax.Array  # (BDF3's predictor)
    gap: jax.Array  # z̄ⁿ
    gap_prev: jax.Array
    gap_prev2: jax.Array
    gap_prev3: jax.Array
    excursion_peak: jax.Array  # max |z̄ - z̄_start| so far (the approach's scale)
    gap_step: jax.Array  # Δz̄ⁿ = z̄ⁿ - z̄ⁿ⁻¹ as solved (BDF2's history; gap - gap_prev rounds it)
    gap_step_prev: jax.Array  # Δz̄ⁿ⁻¹ (BDF3)
    velocity: jax.Array  # dz̄/dt̄ at level n by the step's BDF formula (a free sphere's state)
    velocity_prev: jax.Array
    velocity_prev2: jax.Array
    velocity_prev3: jax.Array
    velocity_peak: jax.Array  # max |v̄| so far
    force: jax.Array  # F̄ⁿ
    force_prev: jax.Array
    force_prev2: jax.Array
    force_prev3: jax.Array
    force_peak: jax.Array  # max F̄ so far (the scale of roundoff in F̄)
    since_restart: jax.Array  # accepted steps since the last (re)start: 0, 1, ≥2
    dt_next: jax.Array  # the controller's proposal
    error_prev: jax.Array  # error ratio of the last accepted step
    last_rejected: jax.Array
    accepted: jax.Array  # counters
    rejected: jax.Array
    status: jax.Array  # RUNNING, DONE, STEP_TOO_SMALL
    entry: jax.Array  # index of the output entry of level n (entry_prev: n-1, entry_prev2: n-2)
    entry_prev: jax.Array
    entry_prev2: jax.Array
    profiles: jax.Array  # p̄ at the requested profile times (P, N)
    profile_gaps: jax.Array  # z̄ at the requested profile times (P,)
    profile_films: jax.Array  # h̄ at the requested profile times (P, N)


class Step(NamedTuple):
    """One output entry per attempt (entry 0: the initial state). A rejected attempt, or one after
    the run ended, repeats the last accepted level, so the entries are sorted in ``t``."""

    t: jax.Array
    force: jax.Array  # F̄ (eq 11b)
    film_center: jax.Array  # h̄ at r̄ = 0
    film_min: jax.Array  # min_i h̄_i
    outflow: jax.Array  # volume flux out through the last face, per unit 2π
    gap: jax.Array  # z̄ (the sphere's position; its approach is z̄0 - z̄)
    velocity: jax.Array  # dz̄/dt̄ (BDF derivative of the step; the free sphere's velocity)
    elastic_energy: jax.Array  # Ū = π Σ A_i p̄_i (Ŵp̄)_i = ½ ∫ p̄ (-w̄) dĀ, units F_s d_c
    dissipation: jax.Array  # viscous power D̄ = 2π Σ_faces g (Δp̄)², same units per t_c
    accepted: jax.Array  # this entry is a new accepted level
    stencil: jax.Array  # entries of levels n-2, n-1 and n (for the interpolant), (3,)
    degree: jax.Array  # of the step's interpolant: 1 (backward Euler), 2 (BDF2), 3 (BDF3)


class Trajectory(NamedTuple):
    """What :func:`rollout` returns: the step entries, the profiles, and how the run ended."""

    steps: Step  # leading axis: max_steps + 1 entries
    profiles: jax.Array  # p̄ at the requested times, (P, N)
    profile_gaps: jax.Array  # z̄ at the requested times, (P,)
    profile_films: jax.Array  # h̄ at the requested times, (P, N)
    status: jax.Array
    accepted: jax.Array
    rejected: jax.Array
    t_final: jax.Array

    @property
    def finished(self):
        """t_end reached (not stopped by the attempt budget or a collapsing step)."""
        return self.status == DONE


def film_thickness(disc: Discretisation, z, pressure):
    """h̄ = z̄ + r̄²/2 - w̄, w̄ = -Ŵp̄ (eqs 8a, 21)."""
    return z + 0.5 * disc.r**2 + disc.influence @ pressure


def displacement(disc: Discretisation, pressure):
    """Surface displacement w̄ = -Ŵp̄ (eq 21); ≤ 0 under positive pressure."""
    return -disc.influence @ pressure


def _film_at_midpoints(disc: Discretisation, film, z):
    """h̄ at the cell midpoints: the rigid part z̄ + r̄²/2 exactly, the elastic part interpolated."""
    elastic = film - z - 0.5 * disc.r**2
    return z + 0.5 * disc.face_r**2 + 0.5 * (elastic[:-1] + elastic[1:])


def _extrapolate_film(h, h_prev, omega):
    """Geometric extrapolation h* = h (h/h_prev)^ω; falls back to h where either is not positive."""
    positive = (h > 0) & (h_prev > 0)
    ratio = jnp.where(positive, h / jnp.where(positive, h_prev, 1.0), 1.0)
    return h * ratio**omega


def face_conductance(disc: Discretisation, h, h_mid):
    """Conductance of each cell [r̄_i, r̄_{i+1}] between its nodes (the flux through the face
    r̄_f = r̄_{i+1/2} is β g (p̄_{i+1} - p̄_i), per unit 2π), from the film h̄ at the nodes and
    h̄_m at the midpoint:

        1/g = (Δr̄/r̄_f²) ∫ r̄ dr̄/h̄³ / Δr̄  by Simpson's rule,
            = (Δr̄/r̄_f²) (r̄_i/h̄_i³ + 4 r̄_f/h̄_m³ + r̄_{i+1}/h̄_{i+1}³)/6.

    Why: integrating r̄h̄³ ∂p̄/∂r̄ = Q(r̄)/β across the cell, Δp̄ = ∫ Q/(β r̄ h̄³) dr̄, with the
    flux Q(r̄) of a uniform source, Q ∝ r̄²: what the squeeze film has (∂h̄/∂t̄ = dz̄/dt̄ outside
    the contact) and what every axisymmetric flow has near the axis. The harmonic mean of h̄³
    rather than the arithmetic one: the arithmetic mean of nodal h̄³ overestimates the
    conductance by ~(3Δh̄/h̄)²/8, 2 % per cell on the geometric outer mesh where h̄ ~ r̄². The
    radius inside the mean (r̄_f ∫ dr̄/h̄³ was used before): on the outer mesh, whose cells are a
    fixed fraction of r̄, leaving it out was an O((growth - 1)²) error of the squeeze film's
    force, 1.0e-3 at growth 1.1 (rigid squeeze, β = 10⁶, with the weighted pressure of
    lubjax/_influence.py; 6e-5 with the radius inside). Where the flux is constant
    across a cell instead (the neck of a draining contact) the two differ by O((Δr̄/r̄)²), tiny
    on the fine zone. Including the nodes makes a face close as either node's film closes, as
    the continuous equation does (∂h̄/∂t̄ → 0 where h̄ → 0).
    """
    r = disc.r
    mean = (r[:-1] / h[:-1] ** 3 + 4.0 * disc.face_r / h_mid**3 + r[1:] / h[1:] ** 3) / 6.0
    return disc.face_r**2 / (disc.face_gap * mean)


def face_conductance_extrapolated(disc: Discretisation, film, film_prev, gap, gap_prev, omega):
    """:func:`face_conductance` of the film extrapolated to the new level (eq 19 lags it; BDF2
    extrapolates it geometrically, :func:`_extrapolate_film`)."""
    return _conductance_of_extrapolated(
        disc, lambda h, h1: _extrapolate_film(h, h1, omega), ((film, gap), (film_prev, gap_prev))
    )


def _conductance_of_extrapolated(disc: Discretisation, extrapolate, levels):
    """:func:`face_conductance` of ``extrapolate`` applied to the nodal films and, alike, to the
    midpoint films of ``levels`` ((film, gap) pairs, newest first)."""
    h = extrapolate(*(film for film, _ in levels))
    h_mid = extrapolate(*(_film_at_midpoints(disc, film, gap) for film, gap in levels))
    return face_conductance(disc, h, h_mid)


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
    solve = _factorised(matrix)
    x = solve(rhs)
    p = jnp.concatenate([x[:-1], jnp.zeros(1, x.dtype)])
    return p, x[-1], g, solve


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


def _flux_divergence(g, p):
    """(T p̄)_i = g_{i+1/2}(p̄_{i+1} - p̄_i) - g_{i-1/2}(p̄_i - p̄_{i-1}) (see :func:`linear_step`)."""
    flux = g * (p[1:] - p[:-1])
    zero = jnp.zeros(1, p.dtype)
    return jnp.concatenate([flux, zero]) - jnp.concatenate([zero, flux])


def _bdf_coefficients(order, omega):
    """Variable-step BDF2 (order 2, ω = Δtₙ/Δtₙ₋₁) or backward Euler (order 1)."""
    a0 = jnp.where(order == 2, (1 + 2 * omega) / (1 + omega), 1.0)
    a1 = jnp.where(order == 2, -(1 + omega), -1.0)
    a2 = jnp.where(order == 2, omega**2 / (1 + omega), 0.0)
    return a0, a1, a2


def _bdf3_coefficients(dt, dt1, dt2):
    """Variable-step BDF3: a_j = Δt ℓ_j'(t_{n+1}), ℓ_j the Lagrange basis of the levels
    t_{n+1}, t_n, t_{n-1}, t_{n-2} at distances u = 0, Δt, Δt + Δt₁, Δt + Δt₁ + Δt₂ before
    t_{n+1}; a₀ + a₁ + a₂ + a₃ = 0. Constant steps: 11/6, -3, 3/2, -1/3."""
    u1, u2, u3 = dt, dt + dt1, dt + dt1 + dt2
    a0 = dt * (1.0 / u1 + 1.0 / u2 + 1.0 / u3)
    a1 = -dt * u2 * u3 / (u1 * (u2 - u1) * (u3 - u1))
    a2 = dt * u1 * u3 / (u2 * (u2 - u1) * (u3 - u2))
    a3 = -dt * u1 * u2 / (u3 * (u3 - u1) * (u3 - u2))
    return a0, a1, a2, a3


def _conductance_quadratic(disc: Discretisation, state: State, dt, dt1, dt2):
    """:func:`face_conductance` of the film extrapolated quadratically in ln h̄ through the last
    three levels (BDF3's first stage: third-order, and positive like the geometric one);
    where a level is not positive, the last film."""

    def extrapolate(h, h1, h2):
        positive = (h > 0) & (h1 > 0) & (h2 > 0)
        logs = [jnp.log(jnp.where(positive, x, 1.0)) for x in (h, h1, h2)]
        out = jnp.exp(ctrl.lagrange(dt, (0.0, dt1, dt1 + dt2), logs))
        return jnp.where(positive, out, h)

    levels = ((state.film, state.gap), (state.film_prev, state.gap_prev),
              (state.film_prev2, state.gap_prev2))
    return _conductance_of_extrapolated(disc, extrapolate, levels)


def _next_breakpoint(breakpoints, t, t_end):
    """The first velocity jump after t (or t_end)."""
    later = jnp.where(breakpoints > t, breakpoints, jnp.inf)
    return jnp.minimum(jnp.min(later, initial=jnp.inf), t_end)


def _interpolate(t_query, times, values, degree, xp=jnp):
    """The step's interpolant at t_query ∈ [t1, t2], ``times`` = (t₋₁, t0, t1, t2) and
    ``values`` alike, newest last: of the step's order (its own dense output), linear through the
    last two for a backward-Euler step (degree 1), quadratic through the last three for BDF2 (2),
    cubic through all four for BDF3 (3). ``xp``: jax.numpy, or numpy for results already on the
    host (:func:`evaluate_host`)."""
    tm, t0, t1, t2 = times
    ym, y0, y1, y2 = values
    # Levels a lower degree does not use may coincide with t1 (a segment's first steps): move
    # them so no branch divides by zero (a NaN in an unselected branch would still poison
    # reverse-mode gradients).
    t0 = xp.where(degree == 1, 2.0 * t1 - t2, t0)
    tm = xp.where(degree < 3, 2.0 * t0 - t1, tm)
    x = t_query - t2
    lin = ctrl.lagrange(x, (t2 - t1, 0.0), (y1, y2))
    quad = ctrl.lagrange(x, (t2 - t0, t2 - t1, 0.0), (y0, y1, y2))
    cubic = ctrl.lagrange(x, (t2 - tm, t2 - t0, t2 - t1, 0.0), (ym, y0, y1, y2))
    return xp.where(degree == 1, lin, xp.where(degree == 2, quad, cubic))


def _restart_step(tol: Tolerance, beta):
    """First step at t̄_start and after each velocity jump: the pressure's fast scale 1/β."""
    return tol.initial_step / jnp.maximum(1.0, beta)


def _initial_state(disc, beta, drive, substrate, z0, tol: Tolerance, profile_times) -> State:
    zero = jnp.zeros_like(disc.r)
    n_memory = jnp.shape(substrate.compliance()[1])[0]
    memory = jnp.zeros((n_memory, disc.r.shape[0]), disc.r.dtype)
    dtype = disc.r.dtype
    scalar = functools.partial(jnp.asarray, dtype=dtype)
    integer = functools.partial(jnp.asarray, dtype=jnp.int32)
    z_start = scalar(drive.initial_gap(z0))
    h = film_thickness(disc, z_start, zero)
    v0 = scalar(drive.initial_velocity())
    return State(
        t=scalar(drive.t_start),
        dt_prev=scalar(1.0),
        dt_prev2=scalar(1.0),
        dt_prev3=scalar(1.0),
        pressure=zero,
        pressure_prev=zero,
        pressure_prev2=zero,
        elastic_load=zero,
        elastic_load_prev=zero,
        elastic_load_prev2=zero,
        memory=memory,
        memory_prev=memory,
        memory_prev2=memory,
        film=h,
        film_prev=h,
        film_prev2=h,
        film_prev3=h,
        gap=z_start,
        gap_prev=z_start,
        gap_prev2=z_start,
        gap_prev3=z_start,
        excursion_peak=jnp.zeros_like(z_start),
        gap_step=jnp.zeros_like(z_start),
        gap_step_prev=jnp.zeros_like(z_start),
        velocity=v0,
        velocity_prev=v0,
        velocity_prev2=v0,
        velocity_prev3=v0,
        velocity_peak=jnp.abs(v0),
        force=scalar(0.0),
        force_prev=scalar(0.0),
        force_prev2=scalar(0.0),
        force_prev3=scalar(0.0),
        force_peak=scalar(0.0),
        since_restart=integer(0),
        dt_next=jax.lax.stop_gradient(_restart_step(tol, beta)),
        error_prev=scalar(1.0),
        last_rejected=jnp.asarray(False),
        accepted=integer(0),
        rejected=integer(0),
        status=integer(RUNNING),
        entry=integer(0),
        entry_prev=integer(0),
        entry_prev2=integer(0),
        profiles=jnp.zeros((profile_times.shape[0], disc.r.shape[0]), dtype),
        # (the initial state answers profile times at t̄_start)
        profile_gaps=jnp.full((profile_times.shape[0],), z_start, dtype),
        profile_films=jnp.broadcast_to(h, (profile_times.shape[0], h.shape[0])),
    )


def _entry_of(disc, state: State, outflow, dissipation, accepted, degree, stencil) -> Step:
    elastic = state.film - state.gap - 0.5 * disc.r**2  # Ŵū = -w̄
    return Step(
        t=state.t,
        force=state.force,
        film_center=state.film[0],
        film_min=jnp.min(state.film),
        outflow=outflow,
        gap=state.gap,
        velocity=state.velocity,
        elastic_energy=jnp.pi * jnp.sum(disc.cell_area * state.pressure * elastic),
        dissipation=dissipation,
        accepted=accepted,
        stencil=stencil,
        degree=degree,
    )


def _attempt(
    disc, beta, z0, drive, substrate, t_end, tol: Tolerance, profile_times, state: State, k
):
    """Attempt one step from ``state``; returns the new state and output entry ``k + 1``."""
    t = state.t
    target = _next_breakpoint(drive.breakpoints_array(), t, t_end)
    lands = state.dt_next >= target - t
    t_new = jnp.where(lands, target, t + state.dt_next)
    dt = t_new - t
    dt1, dt2 = state.dt_prev, state.dt_prev2

    # Segment start (since_restart = 0): backward Euler, lagged mobility, no estimate yet.
    # Second step: backward Euler paired with linear extrapolation. Then BDF2 with quadratic.
    # Where the force has decayed below its absolute tolerance (a tail, z̄0 > 1), nothing holds
    # it to a relative error and the steps outgrow its decay time 1/λ: BDF2's roots are complex
    # for Δt̄λ > 1/2, so the uncontrolled tail oscillated through zero (-3e-14 in every z̄0 > 1
    # hold, at any rtol). Backward Euler's factor 1/(1 + Δt̄λ) is positive: the tail decays
    # without changing sign, on the same steps (the film there hardly changes). Only a force
    # that was above the threshold and fell back: one still emerging from zero at the start
    # keeps BDF2 (backward Euler there changed the early steps and, through them, later errors).
    tail = (jnp.abs(state.force) < BACKWARD_EULER_FORCE) & (
        state.force_peak >= BACKWARD_EULER_FORCE
    )
    order = jnp.where((state.since_restart >= 2) & (tol.order >= 2) & ~tail, 2, 1)
    omega = jnp.where(order == 2, dt / dt1, 0.0)
    a0, a1, a2 = _bdf_coefficients(order, omega)
    conductance = face_conductance_extrapolated(
        disc, state.film, state.film_prev, state.gap, state.gap_prev, omega
    )
    step_before = state.gap_step
    # Σ_j a_j z̄ⁿ⁺¹⁻ʲ = a₀Δz̄ + gap_history, in the solved steps (linear_step): -a₂Δz̄ⁿ for BDF2
    gap_history = -a2 * step_before
    # BDF3 (Settings(order=3); static: the programs of orders 1 and 2 compute none of this, only
    # carry the state's extra levels): from the fourth step of a segment on, the variable-step
    # BDF3 formula, with the conductances of the film extrapolated quadratically in ln h̄
    # (third-order, positive) and every history sum one level longer. a₃ is None where the
    # step cannot be BDF3.
    a3 = None
    if tol.order == 3:
        order = jnp.where((state.since_restart >= 3) & (order == 2), 3, order)
        is3 = order == 3
        b0, b1, b2, b3 = _bdf3_coefficients(dt, dt1, dt2)
        a0, a1, a2 = (jnp.where(is3, b, a) for a, b in ((a0, b0), (a1, b1), (a2, b2)))
        a3 = jnp.where(is3, b3, 0.0)
        conductance = jnp.where(
            is3, _conductance_quadratic(disc, state, dt, dt1, dt2), conductance
        )
        # Σ_j a_j z̄ⁿ⁺¹⁻ʲ = a₀Δz̄ - a₂Δz̄ⁿ - a₃(Δz̄ⁿ + Δz̄ⁿ⁻¹)  (Σ a_j = 0)
        gap_history = -a2 * step_before - a3 * (step_before + state.gap_step_prev)
    row = drive.row(
        t, t_new, z0, dt, a0, a1, a2, state.gap, step_before, state.velocity, state.velocity_prev,
        state.force,
        third=None if a3 is None else (a3, state.gap_step_prev, state.velocity_prev2),
    )
    # The substrate's memory (module _substrate): ūⁿ⁺¹ = c p̄ⁿ⁺¹ + Σ_k memory_k; none if elastic.
    j0, jk, lam = substrate.compliance()
    if jnp.shape(jk)[0] == 0:
        # Elastic: ū = p̄; the same arithmetic as without a substrate model (bit for bit:
        # adding zero memory terms changed the rounding, and the fits' convergence with it).
        compliance = None
        known_load = a1 * state.elastic_load + a2 * state.elastic_load_prev
        if a3 is not None:
            known_load = known_load + a3 * state.elastic_load_prev2

        def loads(p):
            return state.memory, p
    else:
        denom = a0 + dt / lam
        creep = dt * jk / lam / denom
        compliance = j0 + jnp.sum(creep)
        history_memory = -a1 * state.memory - a2 * state.memory_prev
        if a3 is not None:
            history_memory = history_memory - a3 * state.memory_prev2
        memory_known = history_memory / denom[:, None]
        known_load = (
            a0 * jnp.sum(memory_known, axis=0)
            + a1 * state.elastic_load
            + a2 * state.elastic_load_prev
        )
        if a3 is not None:
            known_load = known_load + a3 * state.elastic_load_prev2

        def loads(p):
            memory = memory_known + creep[:, None] * p[None, :]
            return memory, j0 * p + jnp.sum(memory, axis=0)

    p, dz, g, solve = linear_step(
        disc, beta, conductance, dt, a0, gap_history, compliance, known_load, row
    )
    # Second stage, on the same factors: the conductances of the film the first stage gives,
    # g(h̄ⁿ⁺¹), replace the extrapolated ones g(h̄*) by one simplified-Newton correction,
    # M δ = (T(g(h̄ⁿ⁺¹)) - T(g(h̄*))) p̄ⁿ⁺¹ (departure from the paper: docstring).
    z_first = state.gap + dz
    h_first = film_thickness(disc, z_first, loads(p)[1])
    g_new = beta * face_conductance(disc, h_first, _film_at_midpoints(disc, h_first, z_first))
    residual = _flux_divergence(g_new - g, p)
    delta = solve(jnp.concatenate([residual[:-1], jnp.zeros(1, p.dtype)]))
    corrected = p + jnp.concatenate([delta[:-1], jnp.zeros(1, p.dtype)])
    dz = dz + delta[-1]
    # The rows now hold as A Δh̄ a₀/Δt̄ = T(g*) p̄_corrected + T(g_new - g*) p̄_first, and T
    # telescopes: the film's volume changes by exactly this outer flux, the one reported.
    outflow = -g[-1] * (corrected[-1] - corrected[-2]) - (g_new[-1] - g[-1]) * (p[-1] - p[-2])
    p, g = corrected, g_new
    memory, load = loads(p)
    z_new = state.gap + dz
    h = film_thickness(disc, z_new, load)
    force = disc.force_weights @ p
    velocity = (a0 * dz + gap_history) / dt
    dissipation = 2.0 * jnp.pi * jnp.sum(g * (p[1:] - p[:-1]) ** 2)

    # Embedded error estimate (Milne's device) on the film at every node, on F̄, and on the
    # sphere's position and velocity where the drive leaves them free.
    dt3 = state.dt_prev3
    factor = ctrl.milne_factor(
        order, dt, dt1, dt2, a0, a1, a2, None if a3 is None else (dt3, a3)
    )

    def milne(new, y, y1, y2, y3):
        level3 = None if a3 is None else (dt3, y3)
        return factor * (new - ctrl.extrapolate(order, dt, dt1, dt2, y, y1, y2, level3))

    h_err = milne(h, state.film, state.film_prev, state.film_prev2, state.film_prev3)
    scale_h = tol.atol + tol.rtol * jnp.maximum(jnp.abs(h), jnp.abs(state.film))
    f_err = milne(force, state.force, state.force_prev, state.force_prev2, state.force_prev3)
    # The force is held to rtol relative to itself down to force_floor × its peak so far, and
    # to rtol × that floor below it. A decaying tail far below the peak is not resolvable
    # anyway: the solve's rounding (~1e-14 of the peak) made steps collapse at F̄ ~ 1e-10 of
    # the peak with rtol = 1e-7, and a measured travel's quantisation drives a force ~1e-7 of
    # the peak that relative control chased through 10⁴ steps.
    magnitude = jnp.maximum(
        jnp.maximum(jnp.abs(force), jnp.abs(state.force)), tol.force_floor * state.force_peak
    )
    # In a decaying tail (z̄0 > 1: F̄ ∝ e^{-θ}, θ = cβt̄) the relative local errors add up: the
    # relative global error grows with the e-folds already decayed, and at rtol per step it
    # reached 2-3 % where F̄ had fallen to 10⁻⁶ of its peak. So the force's relative tolerance
    # is divided by 1 + TAIL_TIGHTENING × the decades D decayed below the peak. With local
    # errors c Δθ³ ≤ tolerance the global error grows like ∫(1 + 3D)^{-2/3} dθ instead of θ:
    # 0.28 of it at 10⁻⁶ (rtol/19 there), for twice the steps in the tail. At a plateau the
    # tolerance stays rtol, where a tighter one chased the force's rounding in the thinnest
    # films (β = 10⁶).
    tiny = jnp.finfo(magnitude.dtype).tiny
    decades = jnp.log10(
        jnp.maximum(jnp.maximum(state.force_peak, magnitude), tiny) / jnp.maximum(magnitude, tiny)
    )
    scale_f = FORCE_ATOL + tol.rtol * magnitude / (1.0 + TAIL_TIGHTENING * decades)
    # A force emerging from exactly zero (a quiet stretch) has no relative error to estimate
    # until it is nonzero; the film criterion covers that step. A start of motion should be a
    # breakpoint of the history (the restart resolves it); SampledTravel finds it. A prescribed
    # force has no error of the solver's.
    check_force = (state.force != 0) & (not drive.prescribes_force)
    force_error = jnp.where(check_force, jnp.abs(f_err) / scale_f, 0.0)
    error = jnp.maximum(jnp.max(jnp.abs(h_err) / scale_h), force_error)
    gap_start = jnp.asarray(drive.initial_gap(z0), z_new.dtype)
    excursion = jnp.maximum(state.excursion_peak, jnp.abs(z_new - gap_start))
    if not drive.prescribes_gap:
        # A free gap (force control, spring, free sphere): its approach z̄_start - z̄ is what
        # the run reports, and it is a small part of the film it sits in (under 30 mN on the
        # paper's tribometer, 1 d_c out of 5.5): held only through h̄(0) relative to the film,
        # it was 4× rtol of the final approach off, on steps that never saw it. So the gap is
        # held to rtol relative to its largest excursion from the start so far.
        z_err = milne(z_new, state.gap, state.gap_prev, state.gap_prev2, state.gap_prev3)
        error = jnp.maximum(error, jnp.abs(z_err) / (tol.atol + tol.rtol * excursion))
    if drive.inertia:
        # The free sphere's velocity is a state of its own ODE: control it relative to the
        # largest speed so far (it passes through zero at the turning point).
        v_err = milne(
            velocity, state.velocity, state.velocity_prev, state.velocity_prev2,
            state.velocity_prev3,
        )
        scale_v = tol.atol + tol.rtol * jnp.maximum(
            jnp.maximum(jnp.abs(velocity), jnp.abs(state.velocity)), state.velocity_peak
        )
        error = jnp.maximum(error, jnp.abs(v_err) / scale_v)
    error = jnp.where(state.since_restart == 0, 0.0, error)
    # Positivity is part of acceptance: a step that thins the film through zero (or gives NaN)
    # is retried shorter. So is a negative force (beyond roundoff of the peak) where the drive
    # only squeezes the film (a monotone approach or hold: its pressure pushes back, no
    # cavitation model); BDF2 would otherwise overshoot a fast-decaying force below zero.
    roundoff = FORCE_ATOL + 1e-13 * jnp.maximum(state.force_peak, jnp.abs(force))
    negative_force = drive.force_nonnegative & (force < -roundoff)
    valid = jnp.all(jnp.isfinite(p)) & jnp.isfinite(dz) & jnp.all(h > 0) & ~negative_force
    valid = valid & ~jnp.isnan(error)
    accept = valid & (error <= 1.0)

    step_factor = ctrl.next_step_factor(
        accept, valid, error, state.error_prev, order, state.last_rejected
    )
    restart_step = _restart_step(tol, beta)
    # A segment's first step has no estimate: grow by the largest allowed ratio.
    step_factor = jnp.where(state.since_restart == 0, ctrl.MAX_GROWTH, step_factor)
    dt_next = dt * step_factor
    restart = accept & lands & (t_new < t_end)
    dt_next = jnp.where(restart, restart_step, dt_next)
    # The step sizes are not differentiated (like diffrax's controllers): derivatives are those
    # of the discrete solution on the steps taken. Differentiating the controller's choices
    # adds nothing accurate (those terms are O(tolerance)) and is unstable: the error estimate
    # jumps where a measured travel history has kinks, and its tangent grew to 1e20.
    dt_next = jax.lax.stop_gradient(dt_next)
    # Collapse: so small that it hardly changes t in float64 (tight tolerances legitimately
    # take steps far below the restart step in a power-law start).
    floor = jnp.maximum(1e-12 * restart_step, 1e-13 * jnp.abs(t))
    too_small = ~accept & (dt_next < floor)

    # Profiles requested in (t_n, t_{n+1}]: the step's interpolant of p̄ and z̄.
    degree = jnp.asarray(order, jnp.int32)
    in_step = accept & (profile_times > t) & (profile_times <= t_new)
    times = (t - dt1 - dt2, t - dt1, t, t_new)

    def interpolant(*values):
        return jax.vmap(lambda tq: _interpolate(tq, times, values, degree))(profile_times)

    profiles = jnp.where(
        in_step[:, None],
        interpolant(state.pressure_prev2, state.pressure_prev, state.pressure, p),
        state.profiles,
    )
    profile_gaps = jnp.where(
        in_step, interpolant(state.gap_prev2, state.gap_prev, state.gap, z_new),
        state.profile_gaps,
    )
    profile_films = jnp.where(
        in_step[:, None], interpolant(state.film_prev2, state.film_prev, state.film, h),
        state.profile_films,
    )

    entry = k + 1
    new = State(
        t=t_new,
        dt_prev=dt,
        dt_prev2=dt1,
        dt_prev3=dt2,
        pressure=p,
        pressure_prev=state.pressure,
        pressure_prev2=state.pressure_prev,
        elastic_load=load,
        elastic_load_prev=state.elastic_load,
        elastic_load_prev2=state.elastic_load_prev,
        memory=memory,
        memory_prev=state.memory,
        memory_prev2=state.memory_prev,
        film=h,
        film_prev=state.film,
        film_prev2=state.film_prev,
        film_prev3=state.film_prev2,
        gap=z_new,
        gap_prev=state.gap,
        gap_prev2=state.gap_prev,
        gap_prev3=state.gap_prev2,
        excursion_peak=excursion,
        gap_step=dz,
        gap_step_prev=state.gap_step,
        velocity=velocity,
        velocity_prev=state.velocity,
        velocity_prev2=state.velocity_prev,
        velocity_prev3=state.velocity_prev2,
        velocity_peak=jnp.maximum(state.velocity_peak, jnp.abs(velocity)),
        force=force,
        force_prev=state.force,
        force_prev2=state.force_prev,
        force_prev3=state.force_prev2,
        force_peak=jnp.maximum(state.force_peak, force),
        since_restart=jnp.where(restart, 0, state.since_restart + 1),
        dt_next=dt_next,
        error_prev=jnp.maximum(error, 1e-4),
        last_rejected=jnp.asarray(False),
        accepted=state.accepted + 1,
        rejected=state.rejected,
        status=jnp.where(t_new >= t_end, DONE, RUNNING),
        entry=jnp.asarray(entry, jnp.int32),
        entry_prev=state.entry,
        entry_prev2=state.entry_prev,
        profiles=profiles,
        profile_gaps=profile_gaps,
        profile_films=profile_films,
    )
    kept = state._replace(
        dt_next=dt_next,
        last_rejected=jnp.asarray(True),
        rejected=state.rejected + 1,
        status=jnp.where(too_small, STEP_TOO_SMALL, state.status),
    )
    out_state = jax.tree_util.tree_map(lambda a, b: jnp.where(accept, a, b), new, kept)
    stencil = jnp.stack([state.entry_prev2, state.entry_prev, state.entry])
    out = _entry_of(
        disc,
        out_state,
        jnp.where(accept, outflow, 0.0),
        jnp.where(accept, dissipation, 0.0),
        accept,
        # (a rejected entry repeats the accepted level before it; never read past that level)
        jnp.where(accept, degree, 2),
        stencil,
    )
    return out_state, out


def _idle(disc, state: State, k):
    """An attempt after the run ended: nothing changes."""
    stencil = jnp.stack([state.entry_prev2, state.entry_prev, state.entry])
    zero = jnp.zeros_like(state.t)
    return state, _entry_of(
        disc, state, zero, zero, jnp.asarray(False), jnp.asarray(2, jnp.int32), stencil
    )


def rollout(
    disc: Discretisation,
    beta,
    z0,
    drive,
    t_end,
    tol: Tolerance = DEFAULT_TOLERANCE,
    profile_times=None,
    *,
    substrate=None,
    mode: str = "forward",
) -> Trajectory:
    """Integrate a run from rest to ``t_end`` with error control.

    ``drive``: what moves the sphere (:mod:`lubjax._drives`: ``Travel``, ``Load``, ``Spring``,
    ``FreeSphere``), or a bare travel history (``RampHold``, ``SampledTravel``) for a prescribed
    travel. ``substrate`` (:mod:`lubjax._substrate`): ``HalfSpace()`` (default), ``Layer``,
    ``Viscoelastic``; ``disc`` must come from ``discretise(mesh, substrate)`` (the geometry's
    influence matrix). Every drive and substrate takes this one code path. Pure and
    jit/vmap/jvp-compatible in ``beta``, ``z0``, ``t_end`` and the drive's and substrate's
    leaves. ``mode="reverse"`` also supports vjp / ``jax.grad`` (a checkpointed scan over
    ``tol.max_steps`` attempts). Read values at any times with :func:`evaluate`.
    """
    if mode not in ("forward", "reverse"):
        raise ValueError(f"mode must be 'forward' or 'reverse', got {mode!r}")
    if tol.order not in (1, 2, 3):
        raise ValueError(
            f"order must be 1 (backward Euler), 2 (BDF2) or 3 (BDF3), got {tol.order}"
        )
    dtype = disc.r.dtype
    profile_times = (
        jnp.zeros((0,), dtype) if profile_times is None else jnp.asarray(profile_times, dtype)
    )
    drive = as_drive(drive)
    substrate = as_substrate(substrate)
    # At rest at t_start, where the travel need not be zero (eq 23 starts t̄₁/2 above z̄0; a
    # measured history starts wherever its first sample is).
    state0 = _initial_state(disc, beta, drive, substrate, z0, tol, profile_times)
    zero = jnp.zeros((), dtype)
    first = _entry_of(
        disc, state0, zero, zero, jnp.asarray(True), jnp.asarray(2, jnp.int32),
        jnp.zeros(3, jnp.int32),
    )
    attempt = functools.partial(
        _attempt, disc, beta, z0, drive, substrate, t_end, tol, profile_times
    )
    idle = functools.partial(_idle, disc)

    def body(state, k):
        return jax.lax.cond(state.status == RUNNING, attempt, idle, state, k)

    n = tol.max_steps
    if mode == "reverse":
        final, entries = jax.lax.scan(jax.checkpoint(body), state0, jnp.arange(n))
        steps = jax.tree_util.tree_map(
            lambda a, b: jnp.concatenate([a[None], b]), first, entries
        )
    else:
        # Unwritten entries: t = +inf and NaN values, so a read past the end of an unfinished
        # run gives NaN rather than a stale value.
        def blank(a):
            fill = jnp.inf if a is first.t else (np.nan if a.dtype == dtype else 0)
            return jnp.full((n + 1, *a.shape), fill, a.dtype).at[0].set(a)

        buffers = Step(*(blank(a) for a in first))

        def loop_body(carry):
            state, k, buf = carry
            state, entry = attempt(state, k)
            buf = jax.tree_util.tree_map(lambda b, e: b.at[k + 1].set(e), buf, entry)
            return state, k + 1, buf

        def running(carry):
            state, k, _ = carry
            return (state.status == RUNNING) & (k < n)

        final, _, steps = jax.lax.while_loop(running, loop_body, (state0, jnp.int32(0), buffers))
    return Trajectory(
        steps=steps,
        profiles=final.profiles,
        profile_gaps=final.profile_gaps,
        profile_films=final.profile_films,
        status=final.status,
        accepted=final.accepted,
        rejected=final.rejected,
        t_final=final.t,
    )


def evaluate(steps: Step, times, field: str = "force"):
    """``field`` of the run at ``times`` by the stepper's own interpolant (of each step's order:
    cubic for BDF3 steps, quadratic for BDF2, linear for backward Euler). Times past the end of
    the run give NaN; before the start, the initial value. Differentiable, vmappable;
    independent of which times are asked.
    """
    return _evaluate(jnp, steps, times, field)


def evaluate_host(steps: Step, times, field: str = "force") -> np.ndarray:
    """:func:`evaluate` in NumPy, for a finished run on the host: the same arithmetic without
    compiling anything (compiling even this small program costs ~0.2 s, a fresh ``relax``
    call's error estimate and every new length of ``Result.at``'s times paid it)."""
    steps = Step(*(np.asarray(a) for a in steps))
    return _evaluate(np, steps, np.asarray(times, np.float64), field)


def _evaluate(xp, steps: Step, times, field):
    values = getattr(steps, field)
    times = xp.asarray(times, values.dtype)
    k = xp.clip(xp.searchsorted(steps.t, times, side="left"), 0, steps.t.shape[0] - 1)
    im, i0, i1 = steps.stencil[k, 0], steps.stencil[k, 1], steps.stencil[k, 2]
    degree = xp.where(i0 == i1, 1, steps.degree[k])
    with np.errstate(invalid="ignore", divide="ignore"):  # NumPy: the unselected branch
        at = _interpolate(
            times, (steps.t[im], steps.t[i0], steps.t[i1], steps.t[k]),
            (values[im], values[i0], values[i1], values[k]), degree, xp,
        )
    at = xp.where(k == 0, values[0], at)
    # An unfinished scan run repeats its last level: nothing is known past it.
    return xp.where(times > steps.t[-1], xp.nan, at)

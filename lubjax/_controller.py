r"""Step-size control: the tolerance, the error norm, the PI controller, and how a run ends.

A run's :class:`Controller` is three calls, with its memory in an opaque
:class:`ControllerState` (the running peaks inside)::

    state    = controller.init(velocity, dtype)
    attempt  = controller.propose(state, t, history)     # t_new, lands, order
    decision = controller.adapt(state, t, attempt, candidate, history, status)

``propose`` lands the attempt on the history's next velocity jump (:func:`propose_end`) and picks
its formula (:func:`choose_order`: backward Euler where the film collapses too fast for BDF2 to
stay positive, :func:`film_collapses`). ``adapt`` scales the step's Milne estimates
(:mod:`lubjax._multistep`) into one ratio ε (:func:`error_ratio`, ≤ 1: within tolerance), checks
that the candidate may be kept at all (:func:`admissible`: finite, positive film, no negative
force where the drive only squeezes), and decides (:func:`decide`): accept or reject, the next Δt̄,
a restart after a breakpoint, and the run's :class:`Status`.

Controller: the PI controller of Gustafsson (Hairer & Wanner II §IV.2; diffrax's
``PIDController`` with ``pcoeff = 0.4, icoeff = 0.3``), on the error ratio ε:

    Δt_new = Δt · clip(safety · ε_n^{-β₁/k} · ε_{n-1}^{β₂/k}, f_min, f_max),   k = order + 1,

with β₁ = 0.7, β₂ = 0.4. The growth is capped at 1.5: variable-step BDF2 is zero-stable only
for step ratios below 1 + √2, and its error constant and Milne's estimate of it degrade well
before that (docs/design.md); BDF3 is stable on grids whose step ratios stay below 2.553
(Z. Li & H.-l. Liao, "Stability of variable-step BDF2 and BDF3 methods"). A rejected step
shrinks by safety · ε^{-1/k} (at least ×0.1, at most ×0.9); a step that is not admissible
shrinks by ×0.25.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import _multistep as ms
from ._mesh import DEFAULT_RTOL, film_held_by_force
from ._pytree import register

SAFETY = 0.9
BETA_1 = 0.7
BETA_2 = 0.4
MAX_GROWTH = 1.5
MIN_SHRINK = 0.1
INVALID_SHRINK = 0.25

# The force's absolute floor: above its rounding in the solve (~4e-14, where a smooth start makes
# it emerge from zero) and below 1e-6 of the smallest peak force of the mapped range (~1.5e-3 at
# β = 10³, z̄0 = 2). The film's floor is Settings.atol (1e-9): a relative control of the thinnest
# necks (h̄ ~ 1e-7 at β = 10⁶) stalls on their rounding on coarse meshes.
FORCE_ATOL = 1e-12
#: Below this |F̄| (10 × its absolute tolerance) steps are backward Euler (:func:`choose_order`).
BACKWARD_EULER_FORCE = 10.0 * FORCE_ATOL
#: How much the force's tolerance tightens per decade a tail has decayed below its peak.
TAIL_TIGHTENING = 3.0


#: Under the force norm a thin film's local error is still at most this many times rtol of
#: itself (a tenth of the film at the default rtol): ``Tolerance.film_cap``'s default. The
#: film's error hardly moves the force, but its derivatives do (a film drained to 10⁻⁷ moves by
#: ~10⁻³ per unit z̄0 at a node the contact's edge has passed): docs/accuracy.md#derivatives.
FILM_CAP = 1e3
#: The film cap of a run whose derivatives are taken (:meth:`Tolerance.for_tangents`).
TANGENT_FILM_CAP = 100.0


#: How much looser the error estimates' time-coarsened runs are (:meth:`Tolerance.loosened`).
LOOSENING = 8.0


@dataclasses.dataclass(frozen=True)
class Tolerance:
    """What the controller needs. A pytree: the numbers (rtol, atol, initial_step,
    force_floor) are leaves, so a tolerance passed to ``jit`` as an argument is traced and one
    compiled program serves every tolerance; ``order`` and ``max_steps`` shape the program and
    are static. Closed over (as ``sweep`` and the fits do), it is a constant of the program.

    :class:`lubjax.Settings` checks these numbers and documents them in full;
    ``Settings.tolerance()`` builds one.

    Attributes:
        rtol: relative local error tolerance, dimensionless: the step's estimated local error
            e (film h̄ at every node, and F̄) must satisfy |e| ≤ atol + rtol·|value|; a free
            gap z̄, |e| ≤ atol + rtol·max|z̄ - z̄_start|.
        atol: absolute local error tolerance on h̄ and on a free gap z̄ (units of d_c).
        initial_step: the first step after t̄_start and after each velocity jump (units of
            t_c), divided by max(1, β).
        order: 2 (BDF2, default), 1 (backward Euler throughout) or 3 (BDF3 from a segment's
            fourth step).
        max_steps: the attempt budget (accepted + rejected), an integer.
        force_floor: F̄ is held to rtol relative to max(|F̄|, force_floor × its peak so far)
            (dimensionless).
        film_error: "auto" (default), "relative" or "force", what the film's error is
            measured against (:func:`film_scale`).
        film_cap: under the "force" film norm a film's local error is still at most
            film_cap × rtol of itself (default ``FILM_CAP``; a run whose derivatives are taken
            holds it to ``TANGENT_FILM_CAP``, :meth:`for_tangents`).
    """

    rtol: float = DEFAULT_RTOL
    atol: float = 1e-9
    initial_step: float = 1e-5
    order: int = 2
    max_steps: int = 20_000
    force_floor: float = 1e-8
    film_error: str = "auto"
    film_cap: float = FILM_CAP

    def loosened(self) -> Tolerance:
        """The error estimate's time-coarsened partner of this tolerance.

        Returns:
            Tolerance: rtol × ``LOOSENING`` (8; at most 0.1), the rest as is.
        """
        return dataclasses.replace(self, rtol=min(LOOSENING * self.rtol, 0.1))

    def for_tangents(self) -> Tolerance:
        """The tolerance of a run whose derivatives are taken: its film cap at most
        ``TANGENT_FILM_CAP`` (the rest as is).

        Why: under the "force" norm the film inside a near-dry contact may err by a tenth of
        itself, which the force does not feel; its derivatives do. At β = 10⁹, z̄0 = 0.1 the
        tangent dF̄/dz̄0 in a hold to t̄ = 10 is off Hertz's by 4 % to NaN, depending on the
        rounding of z̄0, with a cap of 10³, and within 8·10⁻⁴ with 100 on the finer contact mesh
        :func:`lubjax.mesh_for` gives a differentiated run (docs/accuracy.md#derivatives).
        Neither alone suffices; under the "relative" norm (β < 10⁵ with "auto") nothing changes.

        Returns:
            Tolerance: ``film_cap`` = min(film_cap, ``TANGENT_FILM_CAP``).
        """
        return dataclasses.replace(self, film_cap=jnp.minimum(self.film_cap, TANGENT_FILM_CAP))


register(Tolerance, data=("rtol", "atol", "initial_step", "force_floor", "film_cap"),
         static=("order", "max_steps", "film_error"))
#: The tolerance's defaults: :class:`lubjax.Settings` takes its own from here.
DEFAULT_TOLERANCE = Tolerance()


class Status(enum.IntEnum):
    """How a run stands; :func:`stop_reason` says it in words.

    Attributes:
        RUNNING: still running (inside the loop only).
        DONE: ``t_end`` reached.
        STEP_TOO_SMALL: the step size collapsed (every shorter step was rejected).
        BUDGET_SPENT: the attempt budget (``Settings.max_steps``) ran out before ``t_end``.
    """

    RUNNING = 0
    DONE = 1
    STEP_TOO_SMALL = 2
    BUDGET_SPENT = 3


# Plain integers inside the compiled loop.
RUNNING, DONE, STEP_TOO_SMALL, BUDGET_SPENT = (int(s) for s in Status)

_STOP_REASONS = {
    Status.DONE: "",
    Status.STEP_TOO_SMALL: (
        "the step size collapsed (every shorter step was rejected: the film would lose "
        "positivity, or the local error estimate stayed above the tolerance); refine the "
        "mesh (Settings.dr) or check the parameters"
    ),
    Status.BUDGET_SPENT: (
        "the step budget Settings.max_steps = {max_steps} ran out; raise it "
        "(CLI: --max-steps) or shorten t_end"
    ),
}


def stop_reason(status, max_steps: int) -> str:
    """Why a run stopped before ``t_end``, in words.

    Args:
        status: the run's final :class:`Status` (or its integer, ``Trajectory.status``).
        max_steps: the attempt budget the run had (``Settings.max_steps``), named in the
            sentence.

    Returns:
        The reason and what to change, or '' for a run that reached ``t_end``.

    Raises:
        ValueError: ``status`` is ``RUNNING`` (only a loop in progress is).
    """
    status = Status(int(status))
    if status not in _STOP_REASONS:
        raise ValueError(f"a run still {status.name} has not stopped")
    return _STOP_REASONS[status].format(max_steps=max_steps)


class Peaks(NamedTuple):
    """Running maxima the error norm scales by."""

    force: jax.Array  # max F̄ so far (the scale of roundoff in F̄)
    velocity: jax.Array  # max |v̄| so far
    excursion: jax.Array  # max |z̄ - z̄_start| so far (a free gap's scale)


class ControllerState(NamedTuple):
    """The controller's memory between attempts; the loop carries it without looking inside."""

    dt_next: jax.Array  # the next attempt's Δt̄
    error_prev: jax.Array  # ε of the last accepted step (the PI controller's integral term)
    last_rejected: jax.Array  # do not grow straight after a rejection
    since_restart: jax.Array  # accepted steps since the last (re)start: 0, 1, 2, ...
    peaks: Peaks  # running maxima of the accepted levels


class Attempt(NamedTuple):
    """Where the next attempt goes: its end, whether that is a velocity jump (or t_end), and
    its formula."""

    t_new: jax.Array
    lands: jax.Array
    order: jax.Array


class Decision(NamedTuple):
    """What :meth:`Controller.adapt` decides about one attempt."""

    accept: jax.Array
    state: ControllerState  # the controller's state after the attempt, kept or not
    status: jax.Array  # the run's status after the attempt


class Controller(NamedTuple):
    """The step-size controller of one run: :meth:`init`, then per attempt :meth:`propose`
    (where it goes, which formula) and :meth:`adapt` (keep it or not, what next).

    Attributes:
        tol: the :class:`Tolerance`.
        drive: the run's drive (what its error norm and admissibility depend on).
        beta: β (may be traced).
        z0: z̄0 (may be traced).
        t_end: the run's final time t̄.
    """

    tol: Tolerance
    drive: object
    beta: jax.Array
    z0: jax.Array
    t_end: jax.Array

    def init(self, velocity, dtype) -> ControllerState:
        """The state at rest: a restart step, no error history, peaks of the initial level
        (``velocity`` is v̄ at t̄_start)."""
        return ControllerState(
            dt_next=jax.lax.stop_gradient(restart_step(self.tol, self.beta)),
            error_prev=jnp.asarray(1.0, dtype),
            last_rejected=jnp.asarray(False),
            since_restart=jnp.asarray(0, jnp.int32),
            peaks=Peaks(force=jnp.zeros((), dtype), velocity=jnp.abs(velocity),
                        excursion=jnp.zeros_like(self.gap_start(dtype))),
        )

    def gap_start(self, dtype):
        """z̄ at t̄_start."""
        return jnp.asarray(self.drive.initial_gap(self.z0), dtype)

    def propose(self, state: ControllerState, t, history) -> Attempt:
        """The next attempt from the accepted ``history`` at ``t``: :func:`propose_end`
        lands it on a velocity jump, :func:`choose_order` picks its formula."""
        t_new, lands = propose_end(t, state.dt_next, self.drive.breakpoints_array(),
                                   self.t_end)
        previous = history.newest()
        order = choose_order(state, previous.force, state.peaks, self.tol.order, history,
                             t_new - t)
        return Attempt(t_new, lands, order)

    def adapt(self, state: ControllerState, t, attempt: Attempt, candidate, history,
              status) -> Decision:
        """Keep the ``candidate`` of an attempt t → ``attempt.t_new`` or not, and the
        controller's next state: the error norm (:func:`film_scale`, :func:`error_ratio`),
        positivity (:func:`admissible`), the PI decision (:func:`decide`) and, if kept, the
        peaks (:func:`update_peaks`)."""
        level = candidate.level
        previous = history.newest()
        gap_start = self.gap_start(level.gap.dtype)
        film = film_scale(level, previous, self.tol.film_error, self.beta, self.tol.film_cap)
        ratio = error_ratio(candidate.estimate, level, previous, state.peaks, self.tol,
                            self.drive, gap_start, film)
        valid = admissible(level, state.peaks, self.drive)
        d = decide(ratio, valid, state, attempt.order, t, attempt.t_new, attempt.lands,
                   self.t_end, status, restart_step(self.tol, self.beta))
        kept = d.accepted._replace(peaks=update_peaks(state.peaks, level, gap_start))
        return Decision(
            accept=d.accept,
            state=jax.tree_util.tree_map(functools.partial(jnp.where, d.accept), kept,
                                         d.rejected),
            status=jnp.where(d.accept, d.status_accepted, d.status_rejected),
        )


class Verdict(NamedTuple):
    """What :func:`decide` finds: acceptance, and the controller's state and the run's status
    either way."""

    accept: jax.Array
    accepted: ControllerState  # the controller's state if the step is kept ...
    rejected: ControllerState  # ... and if it is not
    status_accepted: jax.Array
    status_rejected: jax.Array


def restart_step(tol: Tolerance, beta):
    """First step at t̄_start and after each velocity jump: the pressure's fast scale 1/β."""
    return tol.initial_step / jnp.maximum(1.0, beta)


def propose_end(t, dt_next, breakpoints, t_end):
    """The next attempt's end t_new and whether it lands on the next velocity jump (or t_end):
    a step that would pass it is shortened to end there."""
    later = jnp.where(breakpoints > t, breakpoints, jnp.inf)
    target = jnp.minimum(jnp.min(later, initial=jnp.inf), t_end)
    lands = dt_next >= target - t
    return jnp.where(lands, target, t + dt_next), lands


def choose_order(controller: ControllerState, force, peaks: Peaks, max_order: int,
                 history=None, dt=None):
    """The attempt's formula: backward Euler for a segment's first two steps (lagged mobility,
    then linear extrapolation), BDF2 from the third, BDF3 from the fourth where ``max_order`` is
    3.

    Where the force has decayed below its absolute tolerance (a tail, z̄0 > 1), nothing holds it
    to a relative error and the steps outgrow its decay time 1/λ: BDF2's roots are complex for
    Δt̄λ > 1/2, so the uncontrolled tail oscillates through zero. Backward Euler's factor
    1/(1 + Δt̄λ) is positive: the tail decays without changing sign, on the same steps (the film
    there hardly changes). Only a force that was above the threshold and fell back: one still
    emerging from zero at the start keeps BDF2 (backward Euler there changes the early steps
    and, through them, later errors).

    Given the accepted ``history`` and the attempt's ``dt``, a BDF step whose film would not
    stay positive (:func:`film_collapses`) is backward Euler instead.
    """
    tail = (jnp.abs(force) < BACKWARD_EULER_FORCE) & (peaks.force >= BACKWARD_EULER_FORCE)
    order = jnp.where((controller.since_restart >= 2) & (max_order >= 2) & ~tail, 2, 1)
    if max_order == 3:
        order = jnp.where((controller.since_restart >= 3) & (order == 2), 3, order)
    if history is not None:
        order = jnp.where(film_collapses(history, dt, order, max_order), 1, order)
    return order


def film_collapses(history, dt, order, max_order: int):
    """Whether the film at some node fell so fast that the BDF step of ``order`` (2 or 3) and
    length ``dt`` would be negative there whatever the flux: BDF is not positivity-preserving.

    Its film is h̄ⁿ⁺¹ = (-Σ_{j≥1} a_j h̄ⁿ⁺¹⁻ʲ + Δt̄ ∂h̄/∂t̄)/a₀, and the history term
    -Σ_{j≥1} a_j h̄ⁿ⁺¹⁻ʲ extrapolates the film's fall: for BDF2 (a₁ = -(1 + ω),
    a₂ = ω²/(1 + ω), ω = Δt̄/Δt̄ₙ; :func:`lubjax._multistep.bdf12_weights`) it is not positive
    where h̄ⁿ⁻¹ ≥ (1 + 1/ω)² h̄ⁿ, a fourfold fall at equal steps. A film still draining
    (∂h̄/∂t̄ < 0) then crosses zero. Backward Euler's history term is h̄ⁿ itself. This is the
    node a near-dry contact's edge is passing (β ≳ 10⁵: the film there falls from the gap
    outside to ~(βt̄)^{-1/2} within a few steps): there BDF2 went negative every few steps, each
    costing a rejection and the ×0.25 shrink (β = 10⁹, z̄0 = 0.1, on the film's mesh: 1771
    accepted steps to t̄ = 5 without this rule, ~1500 with it, in a one-off comparison).
    Order 1 (or a history too short for the formula): False.
    """
    film, steps = history.film, history.dt
    # BDF2's term multiplied by (1 + ω)/ω² > 0: no division by a first step's zero Δt̄ₙ
    collapse = jnp.any(dt**2 * film[1] >= (dt + steps[0]) ** 2 * film[0])
    if max_order == 3:
        b0, b1, b2, b3 = ms.bdf3_weights(dt, steps[0], steps[1])
        bdf3 = jnp.any(-(b1 * film[0] + b2 * film[1] + b3 * film[2]) / b0 <= 0.0)
        collapse = jnp.where(order == 3, bdf3, collapse)
    return (order > 1) & collapse


def film_scale(level, previous, film_error: str, beta, cap=FILM_CAP):
    """What the film's local error is measured against at each node (times rtol).

    "relative": max(|h̄ⁿ⁺¹|, |h̄ⁿ|), the film's own size. "force" counts the film's error
    through the force it moves: an absolute film error δ inside a contact of indentation
    δ_c = max(-z̄, 0) shifts the elastic indentation by at most δ, and a Hertz force
    (F ∝ δ_c^{3/2}) by 1.5 δ/δ_c of itself. So the film may err by rtol · 2δ_c/3 where that is
    more than rtol of the film, but not by more than ``cap`` × rtol of itself (a tenth of the
    film at the default rtol and ``FILM_CAP``): the force's own tolerance, not a nanometre film
    at the contact's edge (near dry, β ≫ 1, h̄ ~ (βt̄)^{-1/2} ≪ δ_c, the relative control
    spends most steps resolving the film's collapse at each node the contact edge passes), with
    the film still resolved coarsely; a run whose derivatives are taken holds it tighter
    (``TANGENT_FILM_CAP``, :meth:`Tolerance.for_tangents`). Without indentation (z̄ ≥ 0, the
    film carries the force) it is the relative control bit for bit.

    "auto" (the default) is "force" from β = ``NEAR_DRY_BETA`` on and "relative" below, where
    the film inside a contact is what a run reports about it; above, the relative control costs
    several times the steps for a film the default mesh does not resolve (docs/accuracy.md).
    ``Result.unresolved_film()`` flags thin films where the error estimate finds them off.
    ``beta`` may be traced (a sweep mixes the two).
    """
    relative = jnp.maximum(jnp.abs(level.film), jnp.abs(previous.film))
    if film_error == "relative":
        return relative
    through_force = jnp.minimum((2.0 / 3.0) * jnp.maximum(-level.gap, 0.0), cap * relative)
    force = jnp.maximum(relative, through_force)
    return jnp.where(film_held_by_force(film_error, beta), force, relative)


def error_ratio(estimate, level, previous, peaks: Peaks, tol: Tolerance, drive, gap_start,
                film):
    """ε = the largest of the scaled Milne estimates (≤ 1: within tolerance).

    ``estimate``: the step's error estimates (film at every node, force, gap, velocity);
    ``level`` the candidate, ``previous`` the last accepted level (both :class:`Level`);
    ``gap_start``: z̄ at t̄_start; ``film``: what the film's error is measured against at each
    node (:func:`film_scale`).

    * Film: |e| ≤ atol + rtol · ``film`` at every node.
    * Force: rtol relative to itself down to force_floor × its peak so far, and to rtol × that
      floor below it. A decaying tail far below the peak is not resolvable anyway: the solve's
      rounding (~1e-14 of the peak) makes steps collapse at F̄ ~ 1e-10 of the peak with
      rtol = 1e-7, and a measured travel's quantisation drives a force ~1e-7 of the peak that
      relative control would chase through 10⁴ steps.
      In a decaying tail (z̄0 > 1: F̄ ∝ e^{-θ}, θ = cβt̄) the relative local errors add up: the
      relative global error grows with the e-folds already decayed, 2-3 % where F̄ has fallen to
      10⁻⁶ of its peak at rtol per step. So the force's relative tolerance is divided by
      1 + TAIL_TIGHTENING × the decades D decayed below the peak. With local errors c Δθ³ ≤
      tolerance the global error grows like ∫(1 + 3D)^{-2/3} dθ instead of θ: 0.28 of it at
      10⁻⁶ (rtol/19 there), for twice the steps in the tail. At a plateau the tolerance stays
      rtol, where a tighter one chases the force's rounding in the thinnest films (β = 10⁶).
      A force emerging from exactly zero (a quiet stretch) has no relative error to estimate
      until it is nonzero; the film criterion covers that step. A prescribed force has no error
      of the solver's.
    * A free gap (force control, spring, free sphere): its approach z̄_start - z̄ is what a run
      reports, and a small part of the film it sits in (under 30 mN on the paper's tribometer,
      1 d_c out of 5.5): held only through h̄(0), it came out 4× rtol of the final approach off.
      So the gap is held to rtol relative to its largest excursion from the start so far.
    * A free sphere's velocity is a state of its own ODE: held relative to the largest speed so
      far (it passes through zero at the turning point).
    """
    scale_h = tol.atol + tol.rtol * film
    force, force_prev = level.force, previous.force
    magnitude = jnp.maximum(
        jnp.maximum(jnp.abs(force), jnp.abs(force_prev)), tol.force_floor * peaks.force
    )
    tiny = jnp.finfo(magnitude.dtype).tiny
    decades = jnp.log10(
        jnp.maximum(jnp.maximum(peaks.force, magnitude), tiny) / jnp.maximum(magnitude, tiny)
    )
    scale_f = FORCE_ATOL + tol.rtol * magnitude / (1.0 + TAIL_TIGHTENING * decades)
    check_force = (force_prev != 0) & (not drive.prescribes_force)
    force_error = jnp.where(check_force, jnp.abs(estimate.force) / scale_f, 0.0)
    error = jnp.maximum(jnp.max(jnp.abs(estimate.film) / scale_h), force_error)
    if not drive.prescribes_gap:
        excursion = jnp.maximum(peaks.excursion, jnp.abs(level.gap - gap_start))
        error = jnp.maximum(error, jnp.abs(estimate.gap) / (tol.atol + tol.rtol * excursion))
    if drive.inertia:
        scale_v = tol.atol + tol.rtol * jnp.maximum(
            jnp.maximum(jnp.abs(level.velocity), jnp.abs(previous.velocity)), peaks.velocity
        )
        error = jnp.maximum(error, jnp.abs(estimate.velocity) / scale_v)
    return error


def update_peaks(peaks: Peaks, level, gap_start) -> Peaks:
    """The running maxima with an accepted level."""
    return Peaks(
        force=jnp.maximum(peaks.force, level.force),
        velocity=jnp.maximum(peaks.velocity, jnp.abs(level.velocity)),
        excursion=jnp.maximum(peaks.excursion, jnp.abs(level.gap - gap_start)),
    )


def admissible(level, peaks: Peaks, drive):
    """Positivity is part of acceptance: a step that thins the film through zero (or gives
    NaN) is retried shorter. So is a negative force (beyond roundoff of the peak) where the
    drive only squeezes the film (a monotone approach or hold: its pressure pushes back, no
    cavitation model); BDF2 would otherwise overshoot a fast-decaying force below zero."""
    roundoff = FORCE_ATOL + 1e-13 * jnp.maximum(peaks.force, jnp.abs(level.force))
    negative_force = drive.force_nonnegative & (level.force < -roundoff)
    return (
        jnp.all(jnp.isfinite(level.pressure)) & jnp.isfinite(level.gap_step)
        & jnp.all(level.film > 0) & ~negative_force
    )


def decide(error, valid, controller: ControllerState, order, t, t_new, lands, t_end, status,
           first_step) -> Verdict:
    """Accept or reject an attempt t → ``t_new`` of error ratio ``error``; the next Δt̄.

    A segment's first step (after t̄_start or a breakpoint) has no estimate: it is accepted if
    admissible and the next grows by the largest ratio. A step that lands on a breakpoint
    restarts the integration there with ``first_step`` (the pressure adjusts on the fast time
    scale 1/β). The step sizes are not differentiated (like diffrax's controllers): derivatives
    are those of the discrete solution on the steps taken; differentiating the controller's
    choices adds nothing accurate (those terms are O(tolerance)) and is unstable (the estimate
    jumps where a measured history has kinks, and its tangent grows to 1e20). Collapse: a
    rejected step whose successor would hardly change t in float64 (tight tolerances
    legitimately take steps far below the restart step in a power-law start).
    """
    fresh = controller.since_restart == 0
    error = jnp.where(fresh, 0.0, error)
    valid = valid & ~jnp.isnan(error)
    accept = valid & (error <= 1.0)
    factor = next_step_factor(
        accept, valid, error, controller.error_prev, order, controller.last_rejected
    )
    factor = jnp.where(fresh, MAX_GROWTH, factor)
    dt_next = (t_new - t) * factor
    restart = accept & lands & (t_new < t_end)
    dt_next = jax.lax.stop_gradient(jnp.where(restart, first_step, dt_next))
    floor = jnp.maximum(1e-12 * first_step, 1e-13 * jnp.abs(t))
    too_small = ~accept & (dt_next < floor)
    return Verdict(
        accept=accept,
        accepted=controller._replace(
            dt_next=dt_next,
            error_prev=jnp.maximum(error, 1e-4),
            last_rejected=jnp.asarray(False),
            since_restart=jnp.where(restart, 0, controller.since_restart + 1),
        ),
        rejected=controller._replace(dt_next=dt_next, last_rejected=jnp.asarray(True)),
        status_accepted=jnp.where(t_new >= t_end, DONE, RUNNING),
        status_rejected=jnp.where(too_small, STEP_TOO_SMALL, status),
    )


def next_step_factor(accepted, valid, error_ratio, error_ratio_prev, order, last_rejected):
    """Factor multiplying Δt for the next attempt (see module docstring)."""
    k = order + 1.0
    ratio = jnp.maximum(error_ratio, 1e-10)
    ratio_prev = jnp.maximum(error_ratio_prev, 1e-10)
    grow = SAFETY * ratio ** (-BETA_1 / k) * ratio_prev ** (BETA_2 / k)
    # After a rejection do not grow straight away (Hairer & Wanner II, IV.2).
    grow = jnp.clip(grow, 1.0 / MAX_GROWTH, jnp.where(last_rejected, 1.0, MAX_GROWTH))
    shrink = jnp.clip(SAFETY * ratio ** (-1.0 / k), MIN_SHRINK, SAFETY)
    return jnp.where(valid, jnp.where(accepted, grow, shrink), INVALID_SHRINK)

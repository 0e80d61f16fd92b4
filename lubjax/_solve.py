"""The user-facing solver: settings, a precomputed plan, ``relax`` and its result."""

from __future__ import annotations

import dataclasses
import time
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _compiler
from ._checks import (
    FILM_ERRORS,
    any_traced,
    check_auto_none_or_below,
    check_choice,
    check_int_at_least,
    check_parameters,
    check_positive,
    check_positive_or_none,
    check_t_end,
    check_times,
    concrete,
    is_traced,
)
from ._controller import DEFAULT_TOLERANCE, DONE, Tolerance, stop_reason
from ._discretisation import Discretisation, discretise
from ._drives import as_drive
from ._indenter import RampHold, SampledTravel
from ._mesh import Mesh, graded_mesh, mesh_for, mesh_from_tolerance
from ._pytree import register
from ._rollout import Step, evaluate, evaluate_host, rollout
from ._shape import Paraboloid, as_indenter
from ._substrate import HalfSpace, as_substrate
from ._threads import single_threaded_blas


class SolverError(RuntimeError):
    """A run produced NaN or a negative film, or could not reach t_end (:func:`relax` with
    ``check="raise"``); the message says which, and where (``Result.problems()``)."""




@dataclasses.dataclass(frozen=True)
class Settings:
    """Accuracy settings. ``rtol`` is *the* accuracy knob: it sets the time-step controller's
    tolerance and, unless given explicitly, the mesh (``dr``, ``mesh_growth``, ``length``).

    The mesh of a run is :func:`lubjax.mesh_for` (its docstring says which refinement
    ``make_plan``, ``sweep`` and the fits, whose one mesh serves a whole batch, leave out).

    Attributes:
        rtol: relative local error tolerance of every step (dimensionless, in [1e-10, 0.1]),
            on the film h̄ at each node, |error| ≤ atol + rtol·|h̄|, on F̄, |error| ≤ 1e-12 +
            rtol·max(|F̄|, force_floor × peak), and on a free gap z̄ (force control, spring,
            free sphere), |error| ≤ atol + rtol·max|z̄ - z̄_start|. The global error is a few
            times rtol (docs/accuracy.md).
        atol: absolute local error tolerance on h̄ and on a free gap z̄ (units of d_c), in the
            bounds of ``rtol``.
        dr: mesh spacing Δr̄ in the fine zone [0, r_fine] (units of √(R d_c); default: from rtol).
        r_fine: edge r̄ of the uniform fine zone (units of √(R d_c); covers the Hertz radius
            √(1-z̄0) ≤ 1 and its rim).
        length: domain length L̄ with p̄(L̄) = 0 (units of √(R d_c)); force truncation ≈ 4z̄/L̄²
            (default: from rtol).
        mesh_growth: cell-size ratio beyond r_fine (dimensionless; default: from rtol).
        order: 2 (BDF2, default), 1 (backward Euler, the paper's) or 3 (BDF3: fewer steps at
            tight tolerances; benchmarks/work_precision.py charts it).
        initial_step: first step at t̄_start and after each velocity jump, in units of
            min(1, 1/β) (the pressure's fast time scale).
        max_steps: budget of attempted steps (accepted + rejected, an integer ≥ 10); running
            out is an error.
        force_floor: the force is held to rtol relative to max(|F̄|, force_floor × its peak
            so far): pointwise down to 1e-8 of the peak by default. Raise it where a tail far
            below the peak does not matter (fits of noisy data: fitting.FIT_SETTINGS uses 1e-5).
        film_error: what the film's local error is measured against: "auto" (default),
            "relative" below β = 10⁵ (``NEAR_DRY_BETA``) and "force" from there on;
            "relative", the film itself at every node; "force", inside a contact of
            indentation δ_c the larger of the film and 2δ_c/3 (the film's error then counts
            through the force it moves). In a near-dry contact (β ≥ 10⁵) the default takes
            2-8× fewer steps than "relative" for the same force (docs/accuracy.md); the thin
            films inside the contact (which from β = 10⁶ on the default mesh does not resolve
            either way) are then less accurate (``Result.unresolved_film()`` says where the error
            estimate finds them off). The fits keep "relative" (``fitting.FIT_SETTINGS``).
        error_estimate: also run the nested coarse mesh (every other node) at rtol and at
            8·rtol, and return ``Result.force_error`` (about +55 % run time at the default).
        contact_radius: refine the mesh around this r̄ (units of √(R d_c); the Hertz contact's
            edge, where a long hold drains through a thin neck) to what the neck a run ends
            with needs, at most dr/rim_refinement (``NECK_ERROR``), and inside it to what the
            trapped film h̄(0) needs, at most dr/contact_refinement (``DIMPLE_ERROR``)
            (:func:`relax`: hardly any refinement for the default t̄ ≤ 5 run, the full factors
            for holds to t̄ ~ 10³ at β ≳ 10³); 0 refines the axis (a sphere that just
            touches); see :func:`lubjax.graded_mesh`. "auto" (default): :func:`relax` takes
            the edge of the contact the drive ends in, √(travel - z̄0) for a prescribed
            travel, √δ̄ of Hertz under a load, the axis when the sphere stops within 50 dr² of
            the surface; none for a spring, a free sphere, no contact, or a neck the refined
            cell cannot resolve (h̄_min ≈ 0.3/√(β t̄_end) thinner than
            (dr/(4 rim_refinement))^{3/2}: β t̄_end > 6·10⁹ at the defaults; refining there
            only multiplied the steps). None: none. A number must lie in [0, r_fine).
        rim_refinement: refinement factor at the contact's edge (default 14).
        contact_refinement: refinement factor inside the contact (default 3). Together, at
            β = 10³, t̄ = 10³, 14 and 3 bring the late h̄_min to 0.3 % and h̄(0) to 0.5 %; 7 and
            2 left 1.8 % and 1.3 % (benchmarks/accuracy.py).

    Raises:
        ValueError: a setting outside its range (the message names it and the range).

    Example:
        ```python
        import lubjax

        coarse = lubjax.Settings(rtol=1e-3, error_estimate=False)
        dr, growth, length = coarse.mesh_parameters()  # the mesh rtol chose
        assert dr > lubjax.Settings().mesh_parameters()[0]  # coarser than the default
        res = lubjax.relax(100.0, 0.5, t_end=2.0, settings=coarse)
        ```
    """

    rtol: float = DEFAULT_TOLERANCE.rtol
    atol: float = DEFAULT_TOLERANCE.atol
    dr: float | None = None
    r_fine: float = 1.6
    length: float | None = None
    mesh_growth: float | None = None
    order: int = DEFAULT_TOLERANCE.order
    initial_step: float = DEFAULT_TOLERANCE.initial_step
    max_steps: int = DEFAULT_TOLERANCE.max_steps
    force_floor: float = DEFAULT_TOLERANCE.force_floor
    film_error: str = DEFAULT_TOLERANCE.film_error
    error_estimate: bool = True
    contact_radius: float | str | None = "auto"
    rim_refinement: float = 14.0
    contact_refinement: float = 3.0

    def __post_init__(self):
        for name in ("rtol", "atol", "r_fine", "initial_step", "force_floor", "rim_refinement",
                     "contact_refinement"):
            check_positive(f"Settings.{name}", getattr(self, name))
        if not 1e-10 <= self.rtol <= 0.1:
            raise ValueError(f"Settings.rtol must be in [1e-10, 0.1], got {self.rtol}")
        check_choice("Settings.order", self.order, (1, 2, 3))
        check_choice("Settings.film_error", self.film_error, FILM_ERRORS)
        check_int_at_least("Settings.max_steps", self.max_steps, 10)
        for name in ("dr", "length", "mesh_growth"):
            check_positive_or_none(f"Settings.{name}", getattr(self, name))
        check_auto_none_or_below("Settings.contact_radius", self.contact_radius, self.r_fine,
                                 "r_fine")

    def mesh_parameters(self) -> tuple[float, float, float]:
        """The mesh's numbers, each the setting where given, else the one rtol chooses
        (docs/model.md, Discretisation: Δr̄ = 0.014 s, growth 1 + 0.15 s with
        s = (rtol/10⁻⁴)^{1/4}, L̄ = √(100/(3 rtol))).

        Returns:
            (Δr̄, growth, L̄): the fine zone's spacing and the domain length (units of
            √(R d_c)) and the cell-size ratio beyond ``r_fine``.
        """
        dr, growth, length = mesh_from_tolerance(self.rtol)
        return (
            self.dr if self.dr is not None else dr,
            self.mesh_growth if self.mesh_growth is not None else growth,
            self.length if self.length is not None else length,
        )

    def mesh(self, contact_radius: float | None = None,
             contact_refinement: float | None = None,
             rim_refinement: float | None = None,
             contact_slope: float | None = None) -> Mesh:
        """The mesh of these settings, refined around a contact's edge where one is given
        (:func:`lubjax.graded_mesh`).

        Args:
            contact_radius: r̄ to refine around (units of √(R d_c)), in [0, r_fine); None
                (default): the numeric ``Settings.contact_radius``, if it is one.
            contact_refinement: refinement factor inside it (dimensionless, ≥ 1); None:
                ``Settings.contact_refinement``.
            rim_refinement: refinement factor at it (dimensionless, ≥ 1); None:
                ``Settings.rim_refinement``. :func:`relax` passes what the run needs.
            contact_slope: inside the contact the spacing may grow to this × r̄ (in (0, 1);
                None, the default: it stays Δr̄/contact_refinement); see
                :func:`lubjax.graded_mesh`.

        Returns:
            lubjax.Mesh: the mesh.

        Raises:
            ValueError: a radius or factor :func:`lubjax.graded_mesh` refuses.
        """
        dr, growth, length = self.mesh_parameters()
        rim = contact_radius
        if rim is None and not isinstance(self.contact_radius, str):
            rim = self.contact_radius
        if rim is None:
            return graded_mesh(dr, self.r_fine, length, growth)
        return graded_mesh(
            dr, self.r_fine, length, growth, rim=rim,
            rim_dr=dr / (self.rim_refinement if rim_refinement is None else rim_refinement),
            contact_dr=dr / (self.contact_refinement if contact_refinement is None
                             else contact_refinement) if rim > 0 else None,
            contact_slope=contact_slope if rim > 0 else None,
        )

    def tolerance(self) -> Tolerance:
        """The step controller's part of the settings.

        Returns:
            lubjax.stepper.Tolerance: rtol, atol, initial_step, order, max_steps,
            force_floor, film_error).
        """
        return Tolerance(
            self.rtol, self.atol, self.initial_step, self.order, self.max_steps, self.force_floor,
            self.film_error,
        )


class Plan(NamedTuple):
    """Everything that does not depend on (β, z̄0): reuse it across runs, fits and sweeps.

    Build it with :func:`make_plan`.

    Attributes:
        disc: the discretisation of ``mesh`` on ``substrate`` (:func:`lubjax.stepper.discretise`).
        tol: the step controller's tolerance (:class:`lubjax.stepper.Tolerance`).
        drive: the drive (``lubjax.Travel``, ``Load``, ``Spring``, ``FreeSphere``).
        t_end: final time t̄ (units of t_c).
        t: output times t̄ of :func:`force_curve` (a 1-D float64 array).
        mesh: the :class:`lubjax.Mesh`.
        substrate: ``lubjax.HalfSpace()`` (default), a ``Layer`` or a ``Viscoelastic``.
        indenter: ``lubjax.Paraboloid()`` (default) or ``lubjax.Sphere(d_c/R)``.
    """

    disc: Discretisation
    tol: Tolerance
    drive: object
    t_end: float
    t: np.ndarray
    mesh: Mesh
    substrate: object = HalfSpace()
    indenter: object = Paraboloid()


def _drive_of(history, drive):
    if history is not None and drive is not None:
        raise ValueError(
            "give either history= (a prescribed travel) or drive=, not both: "
            "drive=lubjax.Travel(history) is the same as history=history"
        )
    return as_drive(drive if drive is not None else history)


def make_plan(
    t_end: float = 5.0,
    *,
    history: RampHold | SampledTravel | None = None,
    drive=None,
    substrate=None,
    settings: Settings | None = None,
    times=None,
    indenter=None,
) -> Plan:
    """Mesh and influence matrix (cached per mesh), tolerance, drive and output times.

    The mesh is ``settings.mesh()``, one for every (β, z̄0) the plan serves: without the
    per-run refinement of :func:`relax` (:func:`lubjax.mesh_for` says what that changes).

    Args:
        t_end: final time t̄ (units of t_c), after the drive's start.
        history: a prescribed travel (default ``RampHold()``).
        drive: instead of ``history``, any drive.
        substrate: ``HalfSpace()`` (default), ``Layer``, ``Viscoelastic``.
        settings: tolerance and mesh (default ``Settings()``).
        times: where :func:`force_curve` reports F̄ (t̄, units of t_c; default 501 equally
            spaced times from the drive's start to ``t_end``).
        indenter: ``Paraboloid()`` (default) or ``Sphere(d_c/R)`` (lubjax/_shape.py).

    Returns:
        Plan: the fixed (not differentiated) half of :func:`force_curve`'s inputs.

    Raises:
        ValueError: both ``history`` and ``drive``, a ``t_end`` not after the start, or
            ``times`` outside [start, t_end] (the message names the parameter).

    Example:
        ```python
        import lubjax
        import numpy as np

        plan = lubjax.make_plan(2.0, settings=lubjax.Settings(rtol=1e-3, error_estimate=False),
                                times=np.linspace(0.0, 2.0, 21))
        force = lubjax.force_curve(plan, 100.0, 0.5)
        assert force.shape == (21,)
        ```
    """
    history = _drive_of(history, drive)
    settings = Settings() if settings is None else settings
    t_start = float(history.t_start)
    t_end = check_t_end(t_end, t_start)
    if times is None:
        times = np.linspace(t_start, t_end, 501)
    times = check_times(times, "times", t_start, t_end)
    mesh = settings.mesh()
    substrate, indenter = as_substrate(substrate), as_indenter(indenter)
    return Plan(discretise(mesh, substrate, indenter), settings.tolerance(), history, t_end, times,
                mesh, substrate, indenter)


def force_curve(plan: Plan, beta, z0, times=None):
    """F̄ at ``times`` (default ``plan.t``): a pure function of (β, z̄0) for ``jit``, ``vmap``,
    ``jax.grad``, ``jacfwd`` and ``jacrev``.

    Args:
        plan: mesh, tolerance, drive and output times (:func:`make_plan`).
        beta: β (eq 8e), in [1e-4, 1e9]; a traced scalar.
        z0: z̄0 = z0/d_c, in [1e-4, 1e3]; a traced scalar.
        times: where to report F̄ (t̄, units of t_c; default ``plan.t``).

    Returns:
        F̄ at ``times`` (a jax array; dimensionless, as ``Result.force``). Times the run did not
        reach (budget exhausted) come back as NaN.

    Example:
        ```python
        import jax
        import lubjax

        plan = lubjax.make_plan(1.0, settings=lubjax.Settings(rtol=1e-3, error_estimate=False),
                                times=[0.5, 1.0])
        peak = lambda beta: lubjax.force_curve(plan, beta, 0.5)[-1]
        dF_dbeta = jax.grad(peak)(100.0)  # sensitivity of F̄(t̄ = 1) to β
        assert float(dF_dbeta) != 0.0
        ```
    """
    times = plan.t if times is None else times
    traj = rollout(
        plan.disc, beta, z0, plan.drive, plan.t_end, plan.tol, substrate=plan.substrate
    )
    return evaluate(traj.steps, times, "force")


#: The error estimate's observed orders: space 3/2 (the √ edge of a Hertz contact limits the
#: second order of the scheme, tests/test_analytic_limits.py), time 1/2 in rtol (each segment
#: starts with backward Euler; BDF2 alone gives 2/3). The lower orders make it conservative.
SPACE_ORDER, TIME_ORDER = 1.5, 0.5
#: Each estimate is the largest over this many accepted steps either side: the true error and
#: its estimate change sign at different times, and a pointwise bound must cover both.
ESTIMATE_WINDOW = 2
#: The safety factor of Roache's grid convergence index (Roache, Verification and Validation in
#: Computational Science and Engineering, 1998: 1.25 for three grids with a verified order, 3
#: for two). Ours are two-level estimates at assumed orders, and the errors are not always in
#: their asymptotic range: with the weighted far field (lubjax/_influence.py) the nested coarse
#: mesh's error at β = 10, z̄0 = 2, t̄ = 0.26 was 1.5× the fine mesh's, not 2^{3/2}, and the
#: time error at 8 rtol 2.2× that at rtol, not 8^{1/2}. With 1.25 the estimate then bounded the
#: force's error at only 76-82 % of the output times for z̄0 = 2; 2 did at 100 % in all 20 cases
#: of benchmarks/accuracy.py while the mobility's extrapolation error (lubjax/_stepper.py) made
#: z̄0 = 2's time error large. With the mobility corrected that error fell 4-13× and what is
#: left changes sign between the rtol and 8 rtol runs: with 2 the bound held at only 81-89 % of
#: the times for z̄0 = 2 (β = 10-1000); with Roache's 3 it holds at 100 % in all 20 cases, at
#: 4.3-8.5× the largest error.
SAFETY_FACTOR = 3.0


def error_estimate(value, coarse, loose):
    """Estimated global error of ``value`` (a run on the mesh at rtol) from the same quantity on
    the nested coarse mesh (every other node) at rtol (``coarse``) and at 8 rtol (``loose``):

        e_space = |y - y_coarse| / (2^{3/2} - 1),   e_time = |y_coarse - y_loose| / (8^{1/2} - 1),

    Richardson's estimates at the orders :data:`SPACE_ORDER` and :data:`TIME_ORDER` (global
    error ∝ Δr̄^{3/2} and ∝ rtol^{1/2}), summed, times :data:`SAFETY_FACTOR`, and spread over
    ±``ESTIMATE_WINDOW`` steps. Measured against converged runs (benchmarks/accuracy.py): the
    force's estimate bounds its error at ≥ 95 % of the output times in every case of the table,
    and overestimates the largest error 4-9 times."""
    space = np.abs(value - coarse) / (2.0**SPACE_ORDER - 1.0)
    time_ = np.abs(coarse - loose) / (8.0**TIME_ORDER - 1.0)
    total = SAFETY_FACTOR * (space + time_)
    padded = np.pad(total, ESTIMATE_WINDOW, mode="edge")
    n = total.size
    return np.max([padded[k:k + n] for k in range(2 * ESTIMATE_WINDOW + 1)], axis=0)


def _check_x64():
    if not jax.config.jax_enable_x64:
        raise RuntimeError(
            "lubjax needs float64 but jax_enable_x64 is off. Call "
            "jax.config.update('jax_enable_x64', True) (importing lubjax does this) and do not "
            "turn it off afterwards."
        )


@dataclasses.dataclass(frozen=True)
class Result:
    """A relaxation run (dimensionless). Arrays are numpy; where a derivative is taken through
    :func:`relax`, the series and profiles are JAX arrays carrying it, and under ``jit`` or
    ``vmap`` every field is traced and the series are the loop's entries (``relax``).

    The per-step series are at the accepted step times ``t``; read any of them at other
    times with :meth:`at` (the stepper's interpolant).

    Attributes:
        beta: β of the run (eq 8e).
        z0: z̄0 = z0/d_c of the run (eq 8e).
        t_end: the requested final time t̄ (units of t_c).
        t: accepted step times t̄ (the controller's), 1-D.
        force: F̄ = 2π∫p̄ r̄ dr̄ at ``t`` (eq 11b; units of F_s).
        film_min: min h̄ over the mesh at ``t`` (units of d_c).
        film_center: h̄(0), the film on the axis, at ``t`` (units of d_c).
        outflow: volume flux through the outer boundary per unit 2π at ``t`` (units of
            R d_c²/t_c).
        gap: z̄, the sphere's position at ``t`` (units of d_c; prescribed by a travel, free
            under other drives).
        velocity: dz̄/dt̄ at ``t`` (units of d_c/t_c).
        elastic_energy: Ū, the substrate's elastic energy at ``t`` (units of F_s d_c).
        dissipation: D̄, the viscous dissipation rate at ``t`` (units of F_s d_c/t_c):
            dŪ/dt̄ + F̄ dz̄/dt̄ = -D̄.
        r: the mesh's nodes r̄ (units of √(R d_c)), N of them.
        profile_times: the requested profile times t̄.
        pressure: p̄ at ``profile_times``, shape (len(profile_times), N) (units of
            (2E*/π)√(d_c/R), eq 7).
        displacement: w̄ at ``profile_times``, same shape (units of d_c; ≤ 0 into the
            substrate).
        film: h̄ = z̄ + r̄²/2 - w̄ at ``profile_times`` (eq 8), same shape (units of d_c).
        finite: no NaN or inf anywhere.
        film_positive: h̄ > 0 at every accepted step.
        finished: ``t_end`` reached (not stopped by the step budget or a collapsing step).
        stop_reason: why the run stopped, in words (:func:`lubjax.stepper.stop_reason`).
        force_error: estimated error of ``force`` at ``t`` (NaN if ``Settings.error_estimate``
            is off), from the nested coarse mesh at rtol and 8 rtol; zero where the drive
            prescribes the force.
        gap_error: the same for z̄ (zero where the drive prescribes the travel).
        film_center_error: the same for h̄(0).
        film_min_error: the same for min h̄. An error near the film itself says the mesh does
            not resolve that film (late thin necks at large β t̄; :meth:`unresolved_film`).
        accepted: the number of accepted steps.
        rejected: the number of rejected step attempts.
        compile_s: wall time of compilation [s] (0 when cached).
        run_s: wall time of the run itself [s].
        steps: the stepper's record of every accepted step (:class:`lubjax.stepper.Step`),
            which :meth:`at` interpolates.
    """

    beta: float
    z0: float
    t_end: float
    t: np.ndarray
    force: np.ndarray
    film_min: np.ndarray
    film_center: np.ndarray
    outflow: np.ndarray
    gap: np.ndarray
    velocity: np.ndarray
    elastic_energy: np.ndarray
    dissipation: np.ndarray
    r: np.ndarray
    profile_times: np.ndarray
    pressure: np.ndarray
    displacement: np.ndarray
    film: np.ndarray
    finite: bool
    film_positive: bool
    finished: bool
    stop_reason: str
    force_error: np.ndarray
    gap_error: np.ndarray
    film_center_error: np.ndarray
    film_min_error: np.ndarray
    accepted: int
    rejected: int
    compile_s: float
    run_s: float
    steps: Step = dataclasses.field(repr=False)

    @property
    def ok(self) -> bool:
        """Whether the run is sound: ``finite``, ``film_positive`` and ``finished``."""
        return self.finite and self.film_positive and self.finished

    def at(self, times, field: str = "force") -> np.ndarray:
        """A per-step series at any times, by the stepper's interpolant.

        Args:
            times: t̄ (units of t_c) in [t̄_start, t_end]; a scalar or a 1-D sequence.
            field: the series: "force" (default), "film_min", "film_center", "outflow",
                "gap", "velocity", "elastic_energy" or "dissipation".

        Returns:
            The series at ``times`` (a 1-D float64 array, in the series' units; a JAX array
            carrying the derivative where one is taken).

        Raises:
            ValueError: an unknown ``field``, or ``times`` not finite or outside the run.
        """
        if field not in _SERIES[1:]:
            raise ValueError(f"field must be one of {', '.join(_SERIES[1:])}; got {field!r}")
        if not any_traced(self.steps):
            times = check_times(times, "times", float(self.t[0]), self.t_end)
            return evaluate_host(self.steps, times, field)
        span = concrete((self.steps.t[0], self.t_end))
        if span is not None:
            times = check_times(times, "times", float(span[0]), float(span[1]))
        return evaluate(self.steps, jnp.asarray(times, jnp.float64), field)

    def problems(self) -> list[str]:
        """What is wrong with the run, in words (empty when :attr:`ok`).

        Returns:
            list[str]: one sentence per problem, NaN or inf, a negative film (where and how
            thin), a run that stopped before ``t_end`` (where and why).
        """
        out = []
        if not self.finite:
            out.append("the solution contains NaN or inf")
        if not self.film_positive:
            i = int(np.nanargmin(self.film_min))
            h, t = self.film_min[i], self.t[i]
            out.append(f"the film went negative (h̄_min = {h:.3g} at t̄ = {t:.4g})")
        if not self.finished:
            out.append(f"the run stopped at t̄ = {self.t[-1]:.4g} < t_end: {self.stop_reason}")
        return out

    def unresolved_film(self, fraction: float = 0.3) -> str | None:
        """Whether the thinnest film is resolved (late necks at large β t̄ may not be).

        Not an error: the force can still be accurate (it is Hertz's there). Two causes: the
        mesh may not resolve a late neck at large β t̄, and ``Settings.film_error`` "force"
        (the default "auto" from β = 10⁵ on) holds thin films inside a contact only through
        the force they move.

        Args:
            fraction: how large an estimated error of min h̄, relative to min h̄ itself, counts
                as unresolved (dimensionless, > 0; default 0.3).

        Returns:
            A note naming the first time ``film_min_error`` exceeds ``fraction`` × min h̄,
            or None where it never does (or where ``Settings.error_estimate`` was off).
        """
        bad = self.film_min_error > fraction * np.abs(self.film_min)
        if not np.any(bad):
            return None
        i = int(np.argmax(bad))
        return (
            f"from t̄ = {self.t[i]:.4g} the thinnest film (h̄_min = {self.film_min[i]:.3g}) is "
            f"not resolved (estimated error {self.film_min_error[i]:.2g}); the force can still "
            "be. If the film matters: a finer Settings.dr (CLI: --dr) resolves a thin neck, and "
            "Settings.film_error=\"relative\" (CLI: --film-error relative) holds "
            "thin films to rtol of themselves"
        )


register(Result, data=tuple(f.name for f in dataclasses.fields(Result)
                           if f.name != "stop_reason"), static=("stop_reason",))

_COMPILED: dict = {}
_ESTIMATED = ("force", "gap", "film_center", "film_min")
_SERIES = ("t", "force", "film_min", "film_center", "outflow", "gap", "velocity",
           "elastic_energy", "dissipation")


def _forward_rollout(d, b, z, h, s, te, pt, t):
    return rollout(d, b, z, h, te, t, pt, substrate=s)


def _lower_rollout(disc, drive, substrate, tol, n_profiles):
    """Trace and lower :func:`relax`'s program for one mesh (β, z̄0, t_end, the profile times
    and the tolerance's numbers are its arguments)."""
    return jax.jit(_forward_rollout).lower(
        disc, 1.0, 1.0, drive, substrate, 1.0, np.zeros(n_profiles), tol
    )


def _compiled_rollouts(runs, history, substrate) -> tuple[list, float]:
    """AOT-compile once per (mesh size, drive and substrate structure, tolerance structure,
    profile count): lets us report compile time apart. The tolerance's numbers are arguments,
    so the error estimate's run at 8·rtol reuses the program of the run at rtol. ``runs``:
    (discretisation, tolerance, profile times) each; the programs not yet compiled are traced
    one after another and compiled side by side (lubjax/_compiler.py). Returns the executables
    and the seconds spent (tracing, lowering and compiling)."""

    def key_of(disc, tol, ptimes):
        leaves, treedef = jax.tree_util.tree_flatten((history, substrate, tol))
        return disc.r.shape[0], treedef, tuple(np.shape(x) for x in leaves), ptimes.size

    def lowerer(d, tol, pt):
        return lambda: _lower_rollout(d, history, substrate, tol, pt.size)

    return _compiler.cached_all(_COMPILED, [key_of(*r) for r in runs],
                                [lowerer(*r) for r in runs])


def relax(
    beta: float,
    z0: float,
    t_end: float = 5.0,
    *,
    history: RampHold | SampledTravel | None = None,
    drive=None,
    substrate=None,
    settings: Settings | None = None,
    profile_times=(),
    check: str = "raise",
    progress=None,
    mesh: Mesh | None = None,
    indenter=None,
) -> Result:
    """Simulate a relaxation test (paper eqs 8, 11b) in dimensionless form, error-controlled.

    A JAX function: ``jax.grad``, ``jacfwd``, ``jvp`` and ``vjp`` act on it directly (in β,
    z̄0 and the drive's and substrate's numbers; the step times, and so ``t_end``, carry no
    derivative), and so do ``jit`` and ``vmap``. Where the values are known (no ``jit`` or
    ``vmap`` around it) the run is checked and refined as always and its :class:`Result`
    holds the accepted steps, its arrays traced where a derivative is taken. Under ``jit`` or
    ``vmap`` nothing is known until the program runs: the mesh is ``mesh`` or the shared
    ``settings.mesh()`` (no per-run refinement, as :func:`make_plan`), the error estimate is
    not made, ``check`` acts as "flag", and the per-step series are the loop's entries padded
    to ``Settings.max_steps + 1`` (read them with :meth:`Result.at`).

    Args:
        beta: β (eq 8e), in [1e-4, 1e9].
        z0: z̄0 = z0/d_c (the initial gap in units of d_c), in [1e-4, 1e3].
        t_end: final time t̄ (units of t_c). Steps grow as the solution slows: a hold to
            t̄ = 10⁶ costs ~1800 steps at β = 100, z̄0 = 0.5 (the neck at the contact edge keeps
            thinning).
        history: indenter travel, ``RampHold()`` (eqs 8c,d; eq 23 with ``t_accel``) or
            ``SampledTravel`` (a measured history).
        drive: instead of ``history``, any drive: ``Travel(history)``, ``Load`` (force
            control, creep), ``Spring`` (a sphere on a spring), ``FreeSphere`` (inertia).
        substrate: ``HalfSpace()`` (default), ``Layer(thickness, poisson, interface)`` (a layer
            on a rigid base), ``Viscoelastic(...)`` (creep compliance; on either).
        settings: tolerance and mesh (defaults: see :class:`Settings`).
        profile_times: times t̄ (units of t_c) at which p̄, w̄, h̄ profiles are returned (by the
            stepper's interpolant: the steps do not depend on them).
        check: "raise" (default) raises SolverError on NaN, a negative film or a run that did
            not reach t_end; "warn" warns; "flag" only sets the flags of :class:`Result`.
        progress: None (quiet, the default), or a callable told each phase as it starts
            ("compiling the solver", "running the solver", "estimating the error"): the
            command line's progress line shows it.
        mesh: the mesh to run on (default: :func:`lubjax.mesh_for`, the one the run needs).
        indenter: ``Paraboloid()`` (default, eq 8a) or ``Sphere(d_c/R)``, the sphere's true
            profile for deep indentation (lubjax/_shape.py); its ε = d_c/R is a leaf that
            ``jit``, ``vmap`` and ``grad`` see.

    Returns:
        Result: F̄, the gap and min h̄ at every accepted step, the profiles at
        ``profile_times``, the estimated errors (with ``Settings.error_estimate``) and the flags.

    Raises:
        ValueError: β, z̄0, ``t_end``, ``profile_times`` or ``check`` out of range (the message
            names the parameter and its range), or both ``history`` and ``drive``.
        SolverError: with ``check="raise"``, NaN, a negative film or a run that did not reach
            ``t_end``.

    Example:
        ```python
        import jax
        import lubjax

        res = lubjax.relax(100.0, 0.5, t_end=2.0, profile_times=[1.0],
                           settings=lubjax.Settings(rtol=1e-3, error_estimate=False))
        assert res.ok and res.film.shape == (1, res.r.size)
        f_end = res.force[-1]  # F̄ at t̄ = 2, during the hold
        # and its sensitivity to z̄0, through relax itself
        slope = jax.grad(lambda z: lubjax.relax(100.0, z, 2.0).at(2.0)[0])(0.5)
        ```
    """
    _check_x64()
    check_choice("check", check, ("raise", "warn", "flag"))
    history = _drive_of(history, drive)
    settings = Settings() if settings is None else settings
    substrate, indenter = as_substrate(substrate), as_indenter(indenter)
    known = concrete((beta, z0, t_end, history, substrate, indenter))
    if known is None:
        return _relax_traced(beta, z0, t_end, history, substrate, settings, profile_times, mesh,
                             indenter)
    beta_v, z0_v, t_end_v, history_v, substrate_v, indenter_v = known
    check_parameters(beta_v, z0_v)
    t_start = float(history_v.t_start)
    t_end_v = check_t_end(t_end_v, t_start)
    ptimes = check_times(profile_times, "profile_times", t_start, t_end_v)
    if mesh is None:
        mesh = mesh_for(settings, drive=history_v, beta=beta_v, z0=z0_v, t_end=t_end_v,
                        indenter=indenter_v)
    disc = discretise(mesh, substrate_v, indenter_v)
    tol = settings.tolerance()
    runs = [(disc, tol, ptimes)]
    if settings.error_estimate:
        coarse = discretise(mesh.coarsened(), substrate_v, indenter_v)
        loose = tol.loosened()
        runs += [(coarse, tol, ptimes[:0]), (coarse, loose, ptimes[:0])]
    # With a derivative to take, the run itself goes through jit with its inputs' derivatives
    # attached; the error estimate's runs are not differentiated.
    differentiated = any_traced((beta, z0, history, substrate, indenter))
    report = progress if progress is not None else (lambda phase: None)
    report("compiling the solver")
    compiled, compile_s = _compiled_rollouts(runs[differentiated:], history_v, substrate_v)
    report("running the solver")
    start = time.perf_counter()
    with single_threaded_blas():
        trajs = [
            jax.block_until_ready(
                fn(d, float(beta_v), float(z0_v), history_v, substrate_v, t_end_v, pt, t))
            for fn, (d, t, pt) in zip(compiled, runs[differentiated:])
        ]
        if differentiated:
            trajs.insert(0, _differentiable_rollout(discretise(mesh, substrate_v, indenter), beta,
                                                    z0, history, substrate, t_end_v, ptimes, tol))
    run_s = time.perf_counter() - start
    if settings.error_estimate:
        report("estimating the error")
    result = _result_of(trajs, disc, beta_v, z0_v, t_end_v, ptimes, tol.max_steps, compile_s,
                        run_s)
    if not result.ok and check != "flag":
        msg = f"relax(beta={beta_v}, z0={z0_v}): " + "; ".join(result.problems())
        if check == "raise":
            raise SolverError(msg)
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    stopped = sorted((float(tr.t_final), int(tr.status)) for tr in trajs[1:]
                     if int(tr.status) != DONE)
    if stopped and result.ok and check != "flag":
        # the run is sound, its error bars are not: NaN after the coarse runs stopped
        warnings.warn(
            f"relax(beta={beta_v}, z0={z0_v}): the error estimate's coarse runs stopped at "
            f"t̄ = {stopped[0][0]:.4g} ({stop_reason(stopped[0][1], tol.max_steps).split(';')[0]}): "
            "force_error and the other estimated errors are NaN after it; raise "
            "Settings.max_steps",
            RuntimeWarning, stacklevel=2)
    return result


#: relax's run with derivatives to take (jit caches its programs per mesh size and drive).
_differentiable_rollout = jax.jit(_forward_rollout)


def _relax_traced(beta, z0, t_end, history, substrate, settings, profile_times, mesh,
                  indenter) -> Result:
    """:func:`relax` under ``jit`` or ``vmap``: one run on ``mesh`` (or the shared mesh), its
    entries as the loop left them, its flags traced."""
    times = np.atleast_1d(np.asarray(profile_times, np.float64))
    if times.ndim != 1 or not np.all(np.isfinite(times)):
        raise ValueError(f"profile_times must be a 1-D sequence of finite numbers, got {times}")
    mesh = settings.mesh() if mesh is None else mesh
    disc = discretise(mesh, substrate, indenter)
    traj = _forward_rollout(disc, beta, z0, history, substrate, t_end, times,
                            settings.tolerance())
    steps = traj.steps
    series = {k: getattr(steps, k) for k in _SERIES}
    kept = steps.accepted & jnp.isfinite(steps.t)
    nan = jnp.full_like(steps.force, jnp.nan)
    return Result(
        beta=beta, z0=z0, t_end=t_end, **series, r=np.asarray(disc.r), profile_times=times,
        pressure=traj.profiles, displacement=_displacement_of(disc, traj), film=traj.profile_films,
        finite=(jnp.all(jnp.isfinite(jnp.where(kept, steps.force, 0.0)))
                & jnp.all(jnp.isfinite(traj.profiles))),
        film_positive=jnp.all(jnp.where(kept, steps.film_min > 0, True)),
        finished=traj.status == DONE, stop_reason="",
        **{f"{f}_error": nan for f in _ESTIMATED},
        accepted=traj.accepted, rejected=traj.rejected, compile_s=0.0, run_s=0.0, steps=steps,
    )


def _displacement_of(disc, traj):
    """w̄ = -Ŵū at the profile times, from h̄ = z̄ + s(r̄) - w̄ (ū ≠ p̄ on a viscoelastic
    substrate)."""
    profile = disc.profile if is_traced(disc.profile) else np.asarray(disc.profile)
    return traj.profile_gaps[:, None] + profile - traj.profile_films


def _errors_of(series, trajs) -> dict:
    """Each estimated series' error from the estimate's coarse runs (NaN where they were not
    run). On the host (evaluate_host): evaluating with jax compiles ~40 small programs."""
    if len(trajs) == 1:
        return {f: np.full_like(series[f], np.nan) for f in _ESTIMATED}
    coarse, loose = (tr.steps for tr in trajs[1:])
    return {
        f: error_estimate(
            series[f],
            evaluate_host(coarse, series["t"], f),
            evaluate_host(loose, series["t"], f),
        )
        for f in _ESTIMATED
    }


def _result_of(trajs, disc, beta, z0, t_end, ptimes, max_steps, compile_s, run_s) -> Result:
    """The :class:`Result` of a run (``trajs[0]``, whose arrays may carry derivatives) and its
    error estimate's runs."""
    traj = trajs[0]
    primal = concrete(traj)
    keep = np.flatnonzero(np.asarray(primal.steps.accepted))
    series = {k: getattr(traj.steps, k)[keep] for k in _SERIES}
    values = {k: np.asarray(getattr(primal.steps, k))[keep] for k in _SERIES}
    traced = any_traced(traj)
    if not traced:
        series = values
    errors = _errors_of(values, trajs)
    status = int(primal.status)
    return Result(
        beta=float(beta),
        z0=float(z0),
        t_end=t_end,
        **series,
        r=np.asarray(disc.r),
        profile_times=ptimes,
        pressure=traj.profiles if traced else np.asarray(traj.profiles),
        displacement=_displacement_of(disc, traj if traced else primal),
        film=traj.profile_films if traced else np.asarray(traj.profile_films),
        finite=bool(np.all(np.isfinite(values["force"]))
                    and np.all(np.isfinite(primal.profiles))),
        film_positive=bool(np.all(values["film_min"] > 0)),
        finished=status == DONE,
        stop_reason=stop_reason(status, max_steps),
        **{f"{f}_error": errors[f] for f in _ESTIMATED},
        accepted=int(primal.accepted),
        rejected=int(primal.rejected),
        compile_s=compile_s,
        run_s=run_s,
        steps=jax.tree_util.tree_map(jnp.asarray, traj.steps),
    )

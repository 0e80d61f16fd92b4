"""What a run returns and how it is read: the output entries, the saver, and evaluation at any
time by the stepper's own interpolant."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._controller import DONE
from ._discretisation import elastic_part
from ._multistep import dense_output
from ._stepper import History


class Profiles(NamedTuple):
    """The profiles requested at the run's profile times, interpolated so far."""

    pressure: jax.Array  # p̄ (P, N)
    gap: jax.Array  # z̄ (P,)
    film: jax.Array  # h̄ (P, N)


class Output(NamedTuple):
    """The saver's state: which output entries hold the levels the history keeps, and the
    profiles interpolated so far."""

    entries: jax.Array  # output entries of levels n, n-1, n-2 (int, (3,))
    profiles: Profiles

class Series(NamedTuple):
    """The per-level values an output entry reports (the float fields of :class:`Entry`)."""

    force: jax.Array
    film_center: jax.Array
    film_min: jax.Array
    outflow: jax.Array
    gap: jax.Array
    velocity: jax.Array
    elastic_energy: jax.Array
    dissipation: jax.Array


class Entry(NamedTuple):
    """One output entry per attempt (entry 0: the initial state). A rejected attempt, or one after
    the run ended, repeats the last accepted level, so the entries are sorted in ``t``.

    In a :class:`Trajectory` every field has a leading axis of ``max_steps + 1`` entries.

    Attributes:
        t: t̄ of the entry (units of t_c).
        force: F̄ (eq 11b; units of F_s).
        film_center: h̄ at r̄ = 0 (units of d_c).
        film_min: min_i h̄_i (units of d_c).
        outflow: volume flux out through the last face, per unit 2π (units of R d_c²/t_c).
        gap: z̄, the sphere's position (units of d_c; its approach is z̄0 - z̄).
        velocity: dz̄/dt̄ (units of d_c/t_c; the step's BDF derivative, or the free sphere's
            velocity).
        elastic_energy: Ū = π Σ A_i p̄_i (Ŵp̄)_i = ½ ∫ p̄ (-w̄) dĀ (units of F_s d_c).
        dissipation: the viscous power D̄ = 2π Σ_faces g (Δp̄)² (units of F_s d_c/t_c).
        accepted: whether this entry is a new accepted level.
        stencil: the entries of levels n-2, n-1 and n, for the interpolant, shape (3,).
        degree: the degree of the step's interpolant: 1 (backward Euler), 2 (BDF2) or
            3 (BDF3).
    """

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
    """What :func:`rollout` returns: the step entries, the profiles, and how the run ended.

    Attributes:
        steps: the :class:`Entry` entries, leading axis ``max_steps + 1``.
        profiles: p̄ at the requested profile times, shape (P, N).
        profile_gaps: z̄ at the requested profile times, shape (P,).
        profile_films: h̄ at the requested profile times, shape (P, N).
        status: how the run ended (:class:`Status` as an integer; :func:`stop_reason`).
        accepted: the number of accepted steps.
        rejected: the number of rejected attempts.
        t_final: the last accepted time t̄ (``t_end`` when it finished).
    """

    steps: Entry  # leading axis: max_steps + 1 entries
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


def series_of(disc, history: History, outflow, dissipation) -> Series:
    """The reported values of a history's newest level."""
    level = history.newest()
    elastic = elastic_part(disc, level.film, level.gap)  # Ŵū = -w̄
    return Series(
        force=level.force,
        film_center=level.film[0],
        film_min=jnp.min(level.film),
        outflow=outflow,
        gap=level.gap,
        velocity=level.velocity,
        elastic_energy=jnp.pi * jnp.sum(disc.cell_area * level.pressure * elastic),
        dissipation=dissipation,
    )


def entry_of(disc, state, outflow, dissipation, accepted, degree, stencil) -> Entry:
    """The output entry of a state's newest level."""
    series = series_of(disc, state.history, outflow, dissipation)
    return Entry(t=state.t, **series._asdict(), accepted=accepted, stencil=stencil,
                degree=degree)


def save_profiles(profiles: Profiles, t, t_new, history: History, candidate,
                  profile_times) -> Profiles:
    """The saver on an accepted step t → t_new: profiles requested in (t, t_new] are the
    step's dense output of p̄, z̄ and h̄."""
    level = candidate.level
    depth = history.pressure.shape[0]  # levels the dense output may use besides the new one
    dts = history.dt
    times = (t - dts[0] - dts[1], t - dts[0], t, t_new)[-(depth + 1):]
    in_step = (profile_times > t) & (profile_times <= t_new)

    def interpolant(new, levels, kept):
        values = (*(levels[j] for j in reversed(range(depth))), new)
        at = jax.vmap(lambda tq: dense_output(tq, times, values, candidate.order))(profile_times)
        return jnp.where(in_step.reshape(-1, *(1,) * (kept.ndim - 1)), at, kept)

    return Profiles(
        pressure=interpolant(level.pressure, history.pressure, profiles.pressure),
        gap=interpolant(level.gap, history.gap, profiles.gap),
        film=interpolant(level.film, history.film, profiles.film),
    )

def blank_steps(first: Entry, n: int, dtype) -> Entry:
    """Entries not yet written: t = +inf and NaN values, so a read past the end of an
    unfinished run gives NaN rather than a stale value."""

    def blank(a):
        fill = jnp.inf if a is first.t else (np.nan if a.dtype == dtype else 0)
        return jnp.full((n + 1, *a.shape), fill, a.dtype).at[0].set(a)

    return Entry(*(blank(a) for a in first))


def evaluate(steps: Entry, times, field: str = "force"):
    """A field of the run at any times, by the stepper's own interpolant (of each step's order:
    cubic for BDF3 steps, quadratic for BDF2, linear for backward Euler).

    Differentiable and vmappable; the values do not depend on which other times are asked.

    Args:
        steps: the run's :class:`Entry` entries (``Trajectory.steps``).
        times: t̄ (units of t_c); a scalar or an array.
        field: a per-step series of :class:`Entry`: "force" (default), "film_min",
            "film_center", "outflow", "gap", "velocity", "elastic_energy" or "dissipation".

    Returns:
        jax.Array: the field at ``times``, shaped as ``times``; NaN past the end of the run,
        the initial value before its start.
    """
    return _evaluate(jnp, steps, times, field)


def evaluate_host(steps: Entry, times, field: str = "force") -> np.ndarray:
    """:func:`evaluate` in NumPy, for a finished run on the host: the same arithmetic without
    compiling anything (compiling even this small program costs ~0.2 s, for every new length
    of ``times``).

    Args:
        steps: the run's :class:`Entry` entries (``Trajectory.steps``; JAX or NumPy arrays).
        times: t̄ (units of t_c); a scalar or an array.
        field: a per-step series of :class:`Entry`, as for :func:`evaluate` (default "force").

    Returns:
        numpy.ndarray: the field at ``times``, float64, shaped as ``times``.
    """
    steps = Entry(*(np.asarray(a) for a in steps))
    return _evaluate(np, steps, np.asarray(times, np.float64), field)


def _evaluate(xp, steps: Entry, times, field):
    values = getattr(steps, field)
    times = xp.asarray(times, values.dtype)
    k = xp.clip(xp.searchsorted(steps.t, times, side="left"), 0, steps.t.shape[0] - 1)
    im, i0, i1 = steps.stencil[k, 0], steps.stencil[k, 1], steps.stencil[k, 2]
    degree = xp.where(i0 == i1, 1, steps.degree[k])
    with np.errstate(invalid="ignore", divide="ignore"):  # NumPy: the unselected branch
        at = dense_output(
            times, (steps.t[im], steps.t[i0], steps.t[i1], steps.t[k]),
            (values[im], values[i0], values[i1], values[k]), degree, xp,
        )
    at = xp.where(k == 0, values[0], at)
    # An unfinished scan run repeats its last level: nothing is known past it.
    return xp.where(times > steps.t[-1], xp.nan, at)

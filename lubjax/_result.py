"""``Result``: what a run returns, and its assembly from the loop's trajectories."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import any_traced, check_times, concrete, is_traced
from ._controller import DONE, stop_reason
from ._estimate import ESTIMATED, errors_of
from ._output import Entry, evaluate, evaluate_host
from ._pytree import register

#: The per-step series of a run, as the stepper's record names them.
SERIES = ("t", "force", "film_min", "film_center", "outflow", "gap", "velocity",
          "elastic_energy", "dissipation")


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
            Profile times the run did not reach are NaN.
        film_positive: h̄ > 0 in ``film``. Every accepted step already has a finite state and a
            positive film (the controller rejects any other); between steps the profiles are
            the step's polynomial interpolant, which can dip below its nodes' values.
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
        steps: the stepper's record of every accepted step (:class:`lubjax.stepper.Entry`),
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
    steps: Entry = dataclasses.field(repr=False)

    @property
    def ok(self) -> bool:
        """Whether the run is sound: ``finished`` and ``film_positive`` (under ``jit`` or
        ``vmap``, a traced boolean like them)."""
        both = self.finished & self.film_positive
        return both if is_traced(both) else bool(both)

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
        if field not in SERIES[1:]:
            raise ValueError(f"field must be one of {', '.join(SERIES[1:])}; got {field!r}")
        if not any_traced(self.steps):
            times = check_times(times, "times", float(self.t[0]), self.t_end)
            return evaluate_host(self.steps, times, field)
        span = concrete((self.steps.t[0], self.t_end))
        if span is not None:
            times = check_times(times, "times", float(span[0]), float(span[1]))
        times = jnp.atleast_1d(jnp.asarray(times, jnp.float64))
        if times.ndim != 1:
            raise ValueError(f"times must be a scalar or a 1-D sequence, got shape {times.shape}")
        return evaluate(self.steps, times, field)

    def problems(self) -> list[str]:
        """What is wrong with the run, in words (empty when :attr:`ok`).

        Returns:
            list[str]: one sentence per problem: a run that stopped before ``t_end`` (where and
            why), a negative film in a profile (where and how thin).
        """
        out = []
        if not self.film_positive:
            k, i = np.unravel_index(int(np.nanargmin(self.film)), self.film.shape)
            out.append(f"the film profile at t̄ = {self.profile_times[k]:.4g} goes negative "
                       f"(h̄ = {self.film[k, i]:.3g} at r̄ = {self.r[i]:.4g})")
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


def displacement_of(disc, traj, film):
    """w̄ = -Ŵū at the profile times, from h̄ = z̄ + s(r̄) - w̄ (ū ≠ p̄ on a viscoelastic
    substrate)."""
    profile = disc.profile if is_traced(disc.profile) else np.asarray(disc.profile)
    return traj.profile_gaps[:, None] + profile - film


def unreached_nan(reached, pressure, film, traced):
    """The profiles, NaN at the profile times the run did not reach (the saver leaves the
    initial state there)."""
    where = jnp.where if traced else np.where
    if not traced:
        pressure, film = np.asarray(pressure), np.asarray(film)
    mask = reached[:, None]
    return where(mask, pressure, np.nan), where(mask, film, np.nan)


def result_of(trajs, disc, beta, z0, t_end, ptimes, max_steps, compile_s, run_s) -> Result:
    """The :class:`Result` of a run (``trajs[0]``, whose arrays may carry derivatives) and its
    error estimate's runs."""
    traj = trajs[0]
    primal = concrete(traj)
    keep = np.flatnonzero(np.asarray(primal.steps.accepted))
    values = {k: np.asarray(getattr(primal.steps, k))[keep] for k in SERIES}
    traced = any_traced(traj)
    # (indexing a jax array by a new number of steps compiles a gather: only where traced)
    series = {k: getattr(traj.steps, k)[keep] for k in SERIES} if traced else values
    errors = errors_of(values, trajs)
    status = int(primal.status)
    reached = (np.asarray(ptimes) <= float(np.max(values["t"]))) | (status == DONE)
    pressure, film = unreached_nan(reached, traj.profiles, traj.profile_films, traced)
    gaps = traj if traced else primal
    return Result(
        beta=float(beta),
        z0=float(z0),
        t_end=t_end,
        **series,
        r=np.asarray(disc.r),
        profile_times=ptimes,
        pressure=pressure,
        displacement=displacement_of(disc, gaps, film),
        film=film,
        film_positive=bool(not np.any(np.asarray(concrete(film)) <= 0)),
        finished=status == DONE,
        stop_reason=stop_reason(status, max_steps),
        **{f"{f}_error": errors[f] for f in ESTIMATED},
        accepted=int(primal.accepted),
        rejected=int(primal.rejected),
        compile_s=compile_s,
        run_s=run_s,
        steps=jax.tree_util.tree_map(jnp.asarray, traj.steps),
    )


def traced_result(traj, disc, r, beta, z0, t_end, times) -> Result:
    """The :class:`Result` of a run under ``jit`` or ``vmap``: its entries as the loop left
    them, its flags traced, no error estimate. ``r``: the mesh's nodes (concrete: under ``jit``
    the discretisation's arrays are traced)."""
    steps = traj.steps
    series = {k: getattr(steps, k) for k in SERIES}
    nan = jnp.full_like(steps.force, jnp.nan)
    last = jnp.max(jnp.where(jnp.isfinite(steps.t), steps.t, -jnp.inf))
    reached = (jnp.asarray(times) <= last) | (traj.status == DONE)
    pressure, film = unreached_nan(reached, traj.profiles, traj.profile_films, True)
    return Result(
        beta=beta, z0=z0, t_end=t_end, **series, r=np.asarray(r), profile_times=times,
        pressure=pressure, displacement=displacement_of(disc, traj, film), film=film,
        film_positive=~jnp.any(film <= 0),
        finished=traj.status == DONE, stop_reason="",
        **{f"{f}_error": nan for f in ESTIMATED},
        accepted=traj.accepted, rejected=traj.rejected, compile_s=0.0, run_s=0.0, steps=steps,
    )

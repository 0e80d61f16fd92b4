r"""Drives: what moves the sphere. A scene picks exactly one.

The semi-discrete Reynolds equation A (dz̄/dt̄ 1 + Ŵ dp̄/dt̄) = β T(h̄) p̄ (docs/model.md, "Drives")
has N-1 rows for p̄_0..p̄_{N-2}; the gap z̄ is one more unknown, so every drive adds one row,
linear in (p̄ⁿ⁺¹, Δz̄ = z̄ⁿ⁺¹ - z̄ⁿ),

    α F̄ⁿ⁺¹ + s Δz̄ = b,        F̄ⁿ⁺¹ = c·p̄ⁿ⁺¹ (eq 11b),

and each step stays one N×N linear solve (the paper's Appendix adds two rows, z̄ and its
velocity; we eliminate the velocity through the BDF formula a₀yⁿ⁺¹ + a₁yⁿ + a₂yⁿ⁻¹ = Δt̄ ẏⁿ⁺¹).

* :class:`Travel` (eqs 8c,d): α = 0, s = 1, b = d̄(tⁿ) - d̄(tⁿ⁺¹).
* :class:`Load` (the paper's Appendix): α = 1, s = 0, b = F̄(tⁿ⁺¹).
* :class:`Spring`, F̄ = K̄ (d̄(t̄) - (z̄0 - z̄)): α = 1, s = -K̄, b = K̄ (d̄ⁿ⁺¹ - d̄ⁿ) + F̄ⁿ.
* :class:`FreeSphere`, dz̄/dt̄ = v̄, dv̄/dt̄ = G (F̄ - W̄) (Davis, Serayssol & Hinch 1986): with
  v̄ⁿ⁺¹ = (a₀Δz̄ - a₂Δz̄ⁿ)/Δt̄ substituted, times Δt̄: α = -Δt̄² G, s = a₀²,
  b = a₀a₂Δz̄ⁿ - Δt̄ (a₁v̄ⁿ + a₂v̄ⁿ⁻¹) - Δt̄² G W̄ (BDF3: b += a₀a₃(Δz̄ⁿ + Δz̄ⁿ⁻¹) - Δt̄ a₃v̄ⁿ⁻²).

Scales (docs/model.md, eq 7): lengths d_c, time t_c, force F_s = 2E* d_c^{3/2} √R/π, each scene
choosing d_c and t_c (:mod:`lubjax._units`); then

    K̄ = k d_c / F_s = π k / (2E* √(R d_c)),    G = F_s t_c² / (m d_c) = 2β/(π St),
    St = m V/(6π η R²) (V = d_c/t_c),          W̄ = W / F_s.

Every drive is a pytree whose numbers are leaves (differentiated, fitted, batched like β, z̄0).
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np

from ._checks import check_number
from ._indenter import RampHold
from ._pytree import register
from ._shape import Paraboloid

#: A collision's thinnest film over its scale z̄0 ε^{2/5} (:meth:`FreeSphere.collision_film`;
#: benchmarks/drives.py measures it).
COLLISION_FILM = 0.24


def _check_history(history, name):
    if not (hasattr(history, "travel") and hasattr(history, "breakpoints_array")):
        raise TypeError(
            f"{name} must be a history such as lubjax.RampHold() or lubjax.SampledTravel(t, "
            f"values), got {type(history).__name__}"
        )


class _Drive:
    """What the stepper asks of a drive (pure, traceable methods). Flags: ``prescribes_gap`` /
    ``prescribes_force`` (leave z̄ / F̄ out of the error estimate), ``inertia`` (the velocity is
    a state), ``force_nonnegative`` (a negative F̄ is an error of the step)."""

    prescribes_gap = False
    prescribes_force = False
    inertia = False
    force_nonnegative = False

    @property
    def t_start(self):
        """t̄ at which the run starts (units of t_c): the history's start."""
        return self.history.t_start

    def breakpoints_array(self):
        """The times t̄ (units of t_c) of the velocity jumps, where steps restart small."""
        return self.history.breakpoints_array()

    def initial_gap(self, z0):
        """z̄ at t̄_start (units of d_c) from z̄0 (eq 8e), the gap before any travel."""
        return z0 - self.history.travel(self.history.t_start)

    def initial_velocity(self):
        """dz̄/dt̄ at t̄_start (units of d_c/t_c): 0, the sphere at rest."""
        return 0.0

    def final_depth(self, z0):
        """How deep (units of d_c; negative: short of the surface) the sphere ends up, for the
        mesh rule (:func:`lubjax.mesh_for`); None where the drive does not tell."""
        return None

    def row(self, step):
        """The closing row's (α, s, b) (module docstring) for ``step``, a
        ``lubjax._stepper.StepRecord``: tⁿ = ``step.t`` → tⁿ⁺¹ = ``step.t_new``, Δt̄ =
        ``step.dt``, BDF weights a₀..a₃ ``step.weights`` (a₃ None without BDF3), accepted
        levels ``step.history`` newest first (``gap_step[0]`` is Δz̄ⁿ as solved)."""
        raise NotImplementedError


def _monotone_approach(history):
    """Whether the history never retracts (a traced boolean for a sampled one)."""
    return getattr(history, "monotone", False)


@dataclasses.dataclass(frozen=True, eq=False)
class Travel(_Drive):
    """Prescribed travel d̄(t̄) toward the substrate: z̄ = z̄0 - d̄(t̄) (eqs 8c,d). The default
    drive; ``relax(history=...)`` wraps its history in it.

    Attributes:
        history: d̄(t̄), the travel (units of d_c) against t̄ (units of t_c): ``RampHold()``
            (default) or ``SampledTravel(t, values)``.

    Raises:
        TypeError: ``history`` is not a history.
    """

    history: object = dataclasses.field(default_factory=RampHold)
    prescribes_gap = True

    def __post_init__(self):
        _check_history(self.history, "Travel(history)")

    def final_depth(self, z0):
        """How deep the sphere ends up: the largest travel less z̄0.

        Args:
            z0: z̄0 = z0/d_c (eq 8e).

        Returns:
            max d̄ - z̄0 (units of d_c; a sampled history's largest sample).
        """
        samples = getattr(self.history, "travel_samples", None)
        final = self.history.travel(np.asarray([1e300])) if samples is None else samples
        return float(np.max(np.asarray(final))) - z0

    @property
    def force_nonnegative(self):
        """Whether a negative F̄ is an error of the step: true under a monotone approach or hold,
        where the film is only squeezed and its pressure pushes back."""
        return _monotone_approach(self.history)

    def row(self, step):
        """The closing row: α = 0, s = 1, b = d̄(tⁿ) - d̄(tⁿ⁺¹) (Δz̄ is prescribed).

        Args:
            step: the step being taken (``lubjax._stepper.StepRecord``).

        Returns:
            (α, s, b).
        """
        # Not (z̄0 - d̄(tⁿ⁺¹)) - z̄ⁿ: that difference of O(1) gaps rounds Δz̄ to the ulp of z̄,
        # all of the squeeze velocity once Δz̄ is tiny (docs/design.md, "Numerical hygiene").
        return 0.0, 1.0, self.history.travel(step.t) - self.history.travel(step.t_new)


@dataclasses.dataclass(frozen=True, eq=False)
class Load(_Drive):
    """Prescribed force F̄(t̄) = ``scale`` × ``history``(t̄) (force control, creep; the paper's
    Appendix).

    The sphere starts at rest at z̄0 under the load F̄(t̄_start) (normally 0).

    Attributes:
        scale: F̄ of the plateau (units of F_s, eq 11b), > 0; default 2π/3, the load whose
            Hertz indentation is d_c.
        history: the load's shape against t̄, any history: ``RampHold()`` (default; ramp from
            0 to 1 over t̄ ∈ [0, 1], then held) or ``SampledTravel(t, values)`` (a sampled load,
            monotone-cubic interpolated).

    Raises:
        ValueError: ``scale`` not > 0.
        TypeError: ``history`` is not a history.
    """

    scale: float = 2.0 * np.pi / 3.0
    history: object = dataclasses.field(default_factory=RampHold)
    prescribes_force = True

    def __post_init__(self):
        check_number("Load.scale", self.scale, 0.0, lo_open=True)
        _check_history(self.history, "Load(history)")

    def initial_gap(self, z0):
        """The gap at t̄_start: z̄0.

        Args:
            z0: z̄0 = z0/d_c (eq 8e).

        Returns:
            z̄0.
        """
        return z0

    def load(self, t):
        """The prescribed force.

        Args:
            t: t̄ (units of t_c); a scalar or an array.

        Returns:
            F̄(t̄) = ``scale`` × ``history``(t̄) (units of F_s).
        """
        return self.scale * self.history.travel(t)

    def final_depth(self, z0):
        """How deep the sphere ends up: Hertz's indentation under the final load.

        Args:
            z0: z̄0 = z0/d_c (unused: the load, not the start, sets the depth).

        Returns:
            δ̄ = (3F̄/(2π))^{2/3} (units of d_c).
        """
        return Paraboloid().depth_under_load(self.final_load())

    def final_load(self) -> float:
        """The load the history ends at.

        Returns:
            F̄(∞) (units of F_s).
        """
        return float(np.asarray(self.load(np.asarray([1e300])))[0])

    def row(self, step):
        """The closing row: α = 1, s = 0, b = F̄(tⁿ⁺¹).

        Args:
            step: the step being taken (``lubjax._stepper.StepRecord``).

        Returns:
            (α, s, b).
        """
        return 1.0, 0.0, self.load(step.t_new)


@dataclasses.dataclass(frozen=True, eq=False)
class Spring(_Drive):
    """A stage with prescribed travel d̄(t̄) holds the sphere through a spring: F̄ = K̄ (d̄(t̄) -
    (z̄0 - z̄)), the sphere lagging the stage by F̄/K̄ (docs/model.md, Drives).

    Attributes:
        stiffness: K̄ = π k/(2E*√(R d_c)), the spring's stiffness (units F_s/d_c), > 0
            (:func:`lubjax.spring_stiffness_bar`); K̄ → ∞ is :class:`Travel`.
        history: d̄(t̄), the stage's travel (units of d_c): ``RampHold()`` (default) or
            ``SampledTravel(t, values)``.

    Raises:
        ValueError: ``stiffness`` not > 0.
        TypeError: ``history`` is not a history.
    """

    stiffness: float = 1.0
    history: object = dataclasses.field(default_factory=RampHold)

    def __post_init__(self):
        check_number("Spring.stiffness", self.stiffness, 0.0, lo_open=True)
        _check_history(self.history, "Spring(history)")

    def final_depth(self, z0):
        """How deep the sphere ends up: where the spring, stretched by the stage's largest
        travel, balances Hertz's force, (2π/3) δ̄^{3/2} = K̄ (max d̄ - z̄0 - δ̄) (the film
        drained: the near-dry limit, where the contact's edge needs the mesh most).

        Args:
            z0: z̄0 = z0/d_c (eq 8e).

        Returns:
            δ̄ (units of d_c); max d̄ - z̄0 (negative) where the stage stops short of the
            surface.
        """
        from scipy.optimize import brentq

        reach = Travel(self.history).final_depth(z0)
        if reach <= 0.0:
            return reach
        # the balance's residual rises monotonically from -K̄ reach at 0 to > 0 at reach
        return brentq(lambda d: (2.0 * math.pi / 3.0) * d**1.5 - self.stiffness * (reach - d),
                      0.0, reach, xtol=1e-14 * reach, rtol=4 * np.finfo(float).eps)

    @property
    def force_nonnegative(self):
        """Whether a negative F̄ is an error of the step: true under a monotone approach."""
        return _monotone_approach(self.history)

    def row(self, step):
        """The closing row: α = 1, s = -K̄, b = K̄ (d̄(tⁿ⁺¹) - d̄(tⁿ)) + F̄ⁿ.

        Args:
            step: the step being taken (``lubjax._stepper.StepRecord``).

        Returns:
            (α, s, b).
        """
        k = self.stiffness
        # The stretch at tⁿ as F̄ⁿ/K̄, not from z̄0 - z̄ⁿ: rounding, as in Travel.row.
        travel = self.history.travel(step.t_new) - self.history.travel(step.t)
        return 1.0, -k, k * travel + step.history.force[0]


@dataclasses.dataclass(frozen=True, eq=False)
class FreeSphere(_Drive):
    """A free sphere with inertia: dz̄/dt̄ = v̄, dv̄/dt̄ = G (F̄ - W̄), starting at z̄0 with the
    film at rest (p̄ = 0).

    Attributes:
        inverse_mass: G = F_s t_c²/(m d_c) = 2β/(π St), dimensionless, > 0, with the Stokes
            number St = m V/(6π η R²), V = d_c/t_c.
        velocity: v̄0, the initial dz̄/dt̄ (units of d_c/t_c; negative: approaching; -1 with
            t_c = x0/V).
        weight: W̄ = W/F_s, a constant load toward the substrate (units of F_s, ≥ 0; weight
            less buoyancy; 0, the default, for a collision without gravity).

    Raises:
        ValueError: ``inverse_mass`` not > 0, ``velocity`` not finite or ``weight`` < 0.
    """

    inverse_mass: float = 1.0
    velocity: float = -1.0
    weight: float = 0.0
    inertia = True

    def __post_init__(self):
        check_number("FreeSphere.inverse_mass", self.inverse_mass, 0.0, lo_open=True)
        check_number("FreeSphere.velocity", self.velocity)
        check_number("FreeSphere.weight", self.weight, 0.0)

    @property
    def t_start(self):
        """t̄ at which the run starts: 0."""
        return 0.0

    def breakpoints_array(self):
        """The velocity jumps: none.

        Returns:
            An empty array.
        """
        return jnp.zeros((0,))

    def final_depth(self, z0):
        """How deep the sphere can press into the substrate, for the mesh rule
        (:func:`lubjax.mesh_for`): Hertz's depth where an approaching sphere's kinetic energy
        is all stored elastically, ½ v̄0²/G = (4π/15) δ̄^{5/2} (the film only takes energy
        away), or where its weight balances Hertz's force, (2π/3) δ̄^{3/2} = W̄, whichever is
        deeper.

        Args:
            z0: z̄0 = z0/d_c (unused: the energy and the weight set the depth).

        Returns:
            δ̄ (units of d_c), ≥ 0.
        """
        kinetic = 0.5 * self.velocity**2 / self.inverse_mass if self.velocity < 0 else 0.0
        rebound = (15.0 * kinetic / (4.0 * math.pi)) ** 0.4
        settled = (3.0 * self.weight / (2.0 * math.pi)) ** (2.0 / 3.0)
        return max(rebound, settled)

    def collision_film(self, z0, beta):
        """The thinnest film of the collision, for the mesh rule: Davis, Serayssol & Hinch's
        scale h̄ ≈ COLLISION_FILM z̄0 ε^{2/5}, with the elasticity parameter of this approach
        ε = 2|v̄0|/(3π² β z̄0^{5/2}) (2/(3π²β) in the collision's scales, z̄0 = 1, v̄0 = -1).

        Args:
            z0: z̄0 = z0/d_c (eq 8e), the starting gap.
            beta: β (eq 8e).

        Returns:
            h̄ (units of d_c), or None for a sphere that is not approaching.
        """
        if self.velocity >= 0:
            return None
        epsilon = 2.0 * abs(self.velocity) / (3.0 * math.pi**2 * beta * z0**2.5)
        return COLLISION_FILM * z0 * epsilon**0.4

    def initial_gap(self, z0):
        """The gap at the start: z̄0.

        Args:
            z0: z̄0 = z0/d_c (eq 8e), the starting gap (1 with the collision scales).

        Returns:
            z̄0.
        """
        return z0

    def initial_velocity(self):
        """dz̄/dt̄ at the start.

        Returns:
            v̄0 = ``velocity``.
        """
        return self.velocity

    def row(self, step):
        """The closing row: α = -Δt̄² G, s = a₀², b = a₀a₂Δz̄ⁿ - Δt̄ (a₁v̄ⁿ + a₂v̄ⁿ⁻¹) -
        Δt̄² G W̄ (the module docstring derives it).

        Args:
            step: the step being taken (``lubjax._stepper.StepRecord``).

        Returns:
            (α, s, b).
        """
        g, dt, (a0, a1, a2, a3) = self.inverse_mass, step.dt, step.weights
        gap_step, velocity = step.history.gap_step, step.history.velocity
        b = a0 * a2 * gap_step[0] - dt * (a1 * velocity[0] + a2 * velocity[1])
        if a3 is not None:
            # BDF3: v̄ⁿ⁺¹ = (a₀Δz̄ - a₂Δz̄ⁿ - a₃(Δz̄ⁿ + Δz̄ⁿ⁻¹))/Δt̄, one more velocity level
            b = b + a0 * a3 * (gap_step[0] + gap_step[1]) - dt * a3 * velocity[2]
        return -(dt**2) * g, a0**2, b - dt**2 * g * self.weight


def restitution(result, at_gap: float = 1.0) -> float:
    """The coefficient of restitution of a :class:`FreeSphere` run, the crossing bisected on
    the stepper's interpolant.

    Args:
        result: the :class:`lubjax.Result` of a run with a :class:`FreeSphere` drive.
        at_gap: z̄ at which the rebound speed is read (units of d_c); default 1, the starting
            gap x0 with the collision scales, as Davis et al. read it.

    Returns:
        e = v̄/|v̄0| when the sphere, moving away, first passes back through ``at_gap``;
        NaN if it does not get back there (no rebound, or the run ended first).
    """
    t, gap, v = (np.asarray(a, float) for a in (result.t, result.gap, result.velocity))
    k = np.flatnonzero((gap[:-1] < at_gap) & (gap[1:] >= at_gap) & (v[1:] > 0))
    if not k.size:
        return float("nan")
    lo, hi = t[k[0]], t[k[0] + 1]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if result.at([mid], "gap")[0] < at_gap:
            lo = mid
        else:
            hi = mid
    return float(result.at([hi], "velocity")[0] / abs(v[0]))


def as_drive(drive_or_history) -> _Drive:
    """A drive for a drive or a history.

    Args:
        drive_or_history: a drive (returned as it is), a bare history (``RampHold``,
            ``SampledTravel``: taken as a prescribed travel) or None (the default
            ``Travel()``).

    Returns:
        The drive.

    Raises:
        TypeError: neither a drive nor a history.
    """
    if drive_or_history is None:
        return Travel()
    if isinstance(drive_or_history, _Drive):
        return drive_or_history
    if hasattr(drive_or_history, "travel"):
        return Travel(drive_or_history)
    raise TypeError(
        "expected a drive (lubjax.Travel, Load, Spring, FreeSphere) or a travel history "
        f"(lubjax.RampHold, SampledTravel), got {type(drive_or_history).__name__}"
    )


register(Travel, ("history",))
register(Load, ("scale", "history"))
register(Spring, ("stiffness", "history"))
register(FreeSphere, ("inverse_mass", "velocity", "weight"))

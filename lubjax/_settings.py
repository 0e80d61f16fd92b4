"""``Settings``: the numbers of a run's accuracy (tolerances, mesh sizes, refinements)."""

from __future__ import annotations

import dataclasses

from ._checks import (
    FILM_ERRORS,
    check_auto_none_or_below,
    check_choice,
    check_int_at_least,
    check_positive,
    check_positive_or_none,
)
from ._controller import DEFAULT_TOLERANCE, Tolerance
from ._mesh import Mesh, mesh_parameters, settings_mesh


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
        return mesh_parameters(self)

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
        return settings_mesh(self, contact_radius, contact_refinement, rim_refinement,
                             contact_slope)

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

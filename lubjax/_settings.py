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
    tolerance and, unless given explicitly, the mesh (``dr``, ``mesh_growth``, ``length``;
    a run's mesh is :func:`lubjax.mesh_for`).

    Attributes:
        rtol: relative local error tolerance of every step (dimensionless, in [1e-10, 0.1]),
            on the film h̄ at each node, |error| ≤ atol + rtol·|h̄|, on F̄, |error| ≤ 1e-12 +
            rtol·max(|F̄|, force_floor × peak), and on a free gap z̄, |error| ≤ atol +
            rtol·max|z̄ - z̄_start| (docs/accuracy.md gives the global error).
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
            so far): pointwise down to 1e-8 of the peak by default (``fitting.FIT_SETTINGS``
            uses 1e-5: a noisy trace's tail far below the peak does not matter).
        film_error: what the film's local error is measured against: "relative", the film
            itself at every node; "force", inside a contact of indentation δ_c the larger of
            the film and 2δ_c/3 (its error counts through the force it moves: 2-8× fewer steps
            near dry, the thin films inside less accurate, ``Result.unresolved_film()``);
            "auto" (default), "relative" below β = ``NEAR_DRY_BETA`` (10⁵), "force" from there.
        error_estimate: also run the nested coarse mesh (every other node) at rtol and at
            8·rtol, and return ``Result.force_error`` (about +55 % run time at the default).
        contact_radius: refine the mesh around this r̄ (units of √(R d_c)), in [0, r_fine), as
            far as the run's final neck and trapped film need, at most dr/rim_refinement and
            dr/contact_refinement (0: the axis; :func:`lubjax.mesh_for`). "auto" (default):
            the edge of the contact the drive ends in, none where there is none or its neck is
            too thin for the refined cell (β t̄_end > 6·10⁹ at the defaults). None: none.
        rim_refinement: refinement factor at the contact's edge (default 14).
        contact_refinement: refinement factor inside the contact (default 3; with 14, the late
            h̄_min and h̄(0) to 0.3 % and 0.5 % at β = t̄ = 10³, docs/design.md "The mesh rule").

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
        (docs/model.md, Discretisation).

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
                None, the default: it stays Δr̄/contact_refinement).

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

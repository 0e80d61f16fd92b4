"""Radial meshes r̄_0 = 0 < ... < r̄_{N-1} = L̄, and the mesh rule (:func:`mesh_for`).

Departs from the paper's uniform [0, 4] (which drops the r̄⁻⁴ pressure tail, 6-20 % of the
force): uniform and fine where the contact lives, then geometric out to a large L̄. The numbers
of the rule are argued in docs/design.md, "The mesh rule".
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._checks import T_END_MAX, check_number, check_parameters
from ._shape import as_indenter


@dataclasses.dataclass(frozen=True)
class Mesh:
    """An immutable, hashable radial mesh (dimensionless r̄ = r/√(R d_c)).

    Attributes:
        nodes: tuple of node positions r̄ (units of √(R d_c)), strictly increasing, first
            node 0, at least 4.

    Raises:
        ValueError: fewer than 4 nodes, a first node other than 0, or nodes not finite and
            strictly increasing.
    """

    nodes: tuple[float, ...]

    def __post_init__(self):
        r = np.asarray(self.nodes, dtype=np.float64)
        if r.ndim != 1 or r.size < 4:
            raise ValueError(f"mesh needs at least 4 nodes, got {r.size}")
        if r[0] != 0.0:
            raise ValueError(f"mesh must start at r=0, got r[0]={r[0]}")
        if not np.all(np.isfinite(r)) or np.any(np.diff(r) <= 0):
            raise ValueError("mesh nodes must be finite and strictly increasing")

    @property
    def r(self) -> np.ndarray:
        """The nodes r̄ as a float64 array."""
        return np.asarray(self.nodes, dtype=np.float64)

    @property
    def size(self) -> int:
        """The number of nodes N."""
        return len(self.nodes)

    @property
    def length(self) -> float:
        """The domain length L̄, the last node (p̄ = 0 there)."""
        return self.nodes[-1]

    def padded(self, size: int) -> Mesh:
        """This mesh with ``size`` nodes: the far field's cells halved from the outside in,
        all but the outermost (whose face gives the outflow through L̄).

        There the pressure is a far-field tail: the extra nodes move a run's force by ~1e-7
        of its peak, so runs whose meshes differ only in size can share one compiled program
        (:func:`padded_size`).

        Args:
            size: the node count, at least :attr:`size`.

        Returns:
            Mesh: the padded mesh (this one where ``size`` equals its size).

        Raises:
            ValueError: ``size`` below the mesh's size.
        """
        if size < self.size:
            raise ValueError(f"padded size must be at least the mesh's {self.size}, got {size}")
        nodes = list(self.nodes)
        cell = len(nodes) - 2
        for _ in range(size - self.size):
            if cell < 1:  # every cell halved once: start again from the outside
                cell = len(nodes) - 2
            nodes.insert(cell, 0.5 * (nodes[cell - 1] + nodes[cell]))
            cell -= 1
        return Mesh(tuple(nodes))

    def coarsened(self) -> Mesh:
        """The nested mesh of every other node, the outer node kept (for error estimates).

        Returns:
            Mesh: the coarser mesh.
        """
        nodes = self.nodes[::2]
        if nodes[-1] != self.nodes[-1]:
            nodes = (*nodes[:-1], self.nodes[-1])
        return Mesh(nodes)


def uniform_mesh(dr: float, length: float) -> Mesh:
    """A uniform mesh of spacing ``dr`` on [0, length] (the paper's: dr = 0.01, length = 4).

    Args:
        dr: Δr̄, the spacing (units of √(R d_c)), 0 < dr < length.
        length: L̄, the domain length (units of √(R d_c)), rounded to a whole number of cells.

    Returns:
        Mesh: the mesh.

    Raises:
        ValueError: not 0 < dr < length.
    """
    if not (dr > 0 and length > 0 and dr < length):
        raise ValueError(f"uniform_mesh needs 0 < dr < length, got dr={dr}, length={length}")
    n = int(round(length / dr))
    return Mesh(tuple(float(x) for x in np.linspace(0.0, n * dr, n + 1)))


#: Growth of the cells away from a refined rim (ratio of neighbouring cell sizes).
RIM_GROWTH = 1.08


def graded_mesh(
    dr: float = 0.02,
    r_fine: float = 1.6,
    length: float = 100.0,
    growth: float = 1.04,
    rim: float | None = None,
    rim_dr: float | None = None,
    contact_dr: float | None = None,
    contact_slope: float | None = None,
) -> Mesh:
    """Uniform spacing ``dr`` on [0, r_fine], then cells growing by ``growth`` up to ``length``;
    optionally refined to ``rim_dr`` around the radius ``rim`` (the neck at a contact's edge;
    ``rim = 0``: the axis) and to ``contact_dr`` inside it (the trapped film).

    Args:
        dr: Δr̄, spacing in the fine zone (units of √(R d_c)), > 0; the zone must cover the
            Hertz contact radius √(1 - z̄0) ≤ 1 and the pressure rim around it.
        r_fine: outer edge of the fine zone (units of √(R d_c)), dr < r_fine < length.
        length: L̄, the domain length (units of √(R d_c); p̄ = 0 there). The dropped force
            fraction is ~ 4 z̄/L̄² (docs/model.md, far field).
        growth: ratio of neighbouring cell sizes outside the fine zone, in (1, 1.5].
        rim: r̄ to refine around (units of √(R d_c)), in [0, r_fine), or None; inside the
            fine zone the spacing is then min(dr, rim_dr + (RIM_GROWTH - 1)|r̄ - rim|), scaled
            so the zone still ends at a node.
        rim_dr: the spacing at ``rim``, in (0, dr]; required with ``rim``.
        contact_dr: with ``rim``, the spacing on [0, rim] is at most contact_dr, in (0, dr],
            and grows by RIM_GROWTH outside it: min(dr, contact_dr + (RIM_GROWTH - 1)
            max(r̄ - rim, 0)).
        contact_slope: with ``contact_dr``, the spacing on [0, rim] is at most
            max(contact_dr, contact_slope · r̄) instead, in (0, 1): a contact of any radius
            a ≤ rim then has at least about 1/contact_slope cells across it (the force of a
            growing dry contact; :func:`mesh_for`).

    Returns:
        Mesh: the mesh.

    Raises:
        ValueError: a spacing, edge, growth or refinement out of the ranges above.
    """
    if not dr > 0:
        raise ValueError(f"dr must be > 0, got {dr}")
    if not (dr < r_fine < length):
        raise ValueError(f"need dr < r_fine < length, got {dr}, {r_fine}, {length}")
    if not (1.0 < growth <= 1.5):
        raise ValueError(f"growth must be in (1, 1.5], got {growth}")
    n_fine = int(math.ceil(r_fine / dr))
    nodes = list(np.arange(n_fine + 1) * dr)
    if contact_dr is not None and not (rim is not None and 0 < contact_dr <= dr):
        raise ValueError(f"contact_dr needs a rim and 0 < contact_dr <= dr, got {contact_dr}")
    if contact_slope is not None and not (contact_dr is not None and 0 < contact_slope < 1):
        raise ValueError(
            f"contact_slope needs a contact_dr and 0 < contact_slope < 1, got {contact_slope}")
    if rim is not None:
        if not (0 <= rim < r_fine and rim_dr is not None and 0 < rim_dr <= dr):
            raise ValueError(
                f"need 0 <= rim < r_fine and 0 < rim_dr <= dr, got rim={rim}, rim_dr={rim_dr}"
            )
        inner = dr if contact_dr is None else contact_dr
        x, fine = 0.0, [0.0]
        while x < nodes[-1]:
            spread = RIM_GROWTH - 1.0
            at = inner if contact_slope is None else max(inner, contact_slope * min(x, rim))
            x += min(dr, rim_dr + spread * abs(x - rim), at + spread * max(x - rim, 0.0))
            fine.append(x)
        nodes = list(np.asarray(fine) * (nodes[-1] / fine[-1]))
    step = dr
    while True:
        step *= growth
        nxt = nodes[-1] + step
        if nxt >= length:
            if length - nodes[-1] < 0.5 * step:
                nodes[-1] = length
            else:
                nodes.append(length)
            break
        nodes.append(nxt)
    return Mesh(tuple(float(x) for x in nodes))


#: The default tolerance, and the mesh it gets (Settings: dr = 0.014, growth 1.15, L̄ = 577).
DEFAULT_RTOL = 1e-4

#: From this β on, ``Settings.film_error="auto"`` (the default) holds the film inside a contact
#: through the force it moves (:func:`lubjax._controller.film_scale`): a near-dry contact.
NEAR_DRY_BETA = 1e5


def film_held_by_force(film_error: str, beta):
    """Whether a run's film error inside a contact is measured through the force
    (``Settings.film_error`` "force", or "auto" from β = ``NEAR_DRY_BETA`` on) rather than
    relative to the film itself. ``beta`` may be traced (then a boolean array)."""
    if film_error == "auto":
        return beta >= NEAR_DRY_BETA
    return film_error == "force"


def mesh_from_tolerance(rtol: float) -> tuple[float, float, float]:
    """(Δr̄, growth, L̄) for a tolerance: Δr̄ and growth - 1 ∝ rtol^{1/4}, the spatial error in
    step with the time error ∝ rtol^{2/3}, and the truncation 4z̄/L̄² below rtol/8 for z̄ ≤ 1
    (docs/design.md, "The mesh rule")."""
    scale = (rtol / DEFAULT_RTOL) ** 0.25
    dr = min(0.05, max(0.002, 0.014 * scale))
    growth = 1.0 + min(0.5, max(0.02, 0.15 * scale))
    length = max(100.0, math.sqrt(100.0 / (3.0 * rtol)))
    return dr, growth, length


def mesh_parameters(settings) -> tuple[float, float, float]:
    """The mesh's numbers of ``settings`` (a :class:`lubjax.Settings`), each the setting where
    given, else the one its rtol chooses (:func:`mesh_from_tolerance`).

    Returns:
        (Δr̄, growth, L̄): the fine zone's spacing and the domain length (units of √(R d_c))
        and the cell-size ratio beyond ``r_fine``.
    """
    dr, growth, length = mesh_from_tolerance(settings.rtol)
    return (
        settings.dr if settings.dr is not None else dr,
        settings.mesh_growth if settings.mesh_growth is not None else growth,
        settings.length if settings.length is not None else length,
    )


#: :func:`mesh_for` rounds a mesh's size up to one of N₀·2^(k/MESH_SIZE_STEPS) (N₀: the
#: settings' plain mesh), at most 9 % more nodes: the runs of a family (many β, z̄0, t̄_end)
#: then share a few compiled programs instead of one per size.
MESH_SIZE_STEPS = 8


def padded_size(size: int, plain: int) -> int:
    """The smallest ⌈N₀·2^(k/MESH_SIZE_STEPS)⌉ ≥ ``size`` (k = 0, 1, ...), N₀ = ``plain``: the
    node count a mesh of ``size`` nodes is padded to when its settings' plain mesh has
    ``plain`` (:meth:`Mesh.padded`)."""
    k = 0
    while True:
        bucket = math.ceil(plain * 2.0 ** (k / MESH_SIZE_STEPS))
        if bucket >= size:
            return bucket
        k += 1


def settings_mesh(settings, contact_radius: float | None = None,
                  contact_refinement: float | None = None,
                  rim_refinement: float | None = None,
                  contact_slope: float | None = None) -> Mesh:
    """The mesh of ``settings`` (:func:`mesh_parameters`), refined around a contact's edge
    where one is given (``Settings.mesh`` documents the arguments); without, a batch's mesh."""
    dr, growth, length = mesh_parameters(settings)
    rim = contact_radius
    if rim is None and not isinstance(settings.contact_radius, str):
        rim = settings.contact_radius
    if rim is None:
        return graded_mesh(dr, settings.r_fine, length, growth)
    return graded_mesh(
        dr, settings.r_fine, length, growth, rim=rim,
        rim_dr=dr / (settings.rim_refinement if rim_refinement is None else rim_refinement),
        contact_dr=dr / (settings.contact_refinement if contact_refinement is None
                         else contact_refinement) if rim > 0 else None,
        contact_slope=contact_slope if rim > 0 else None,
    )


#: Late in a hold the neck at the contact edge thins as h̄_min ≈ NECK_CONSTANT/√(β t̄).
NECK_CONSTANT = 0.3


def final_contact_radius(drive, z0, dr, indenter=None) -> float | None:
    """Edge r̄ of the dry contact the drive ends in, from ``drive.final_depth(z̄0)``: the
    indenter's contact radius (None: Hertz's) for a depth ≥ 0; 0 (the axis) for a sphere short
    of the surface by less than 50 dr²; None otherwise or for a drive that does not tell."""
    final_load = getattr(drive, "final_load", None)
    # (a prescribed load sets the depth through the indenter's shape: Sneddon's under a sphere)
    depth = (as_indenter(indenter).depth_under_load(final_load()) if final_load is not None
             else drive.final_depth(z0))
    if depth is None:
        return None
    if depth >= 0:
        return as_indenter(indenter).contact_radius(depth)
    return 0.0 if -depth < 50.0 * dr**2 else None


def _neck_resolvable(beta, t_end, rim_dr) -> bool:
    """Whether the neck a hold ends with (width ≈ h̄_min^{2/3}) is at least a quarter of the
    refined cell ``rim_dr``; a thinner one is not worth refining."""
    neck = (NECK_CONSTANT / math.sqrt(beta * t_end)) ** (2.0 / 3.0)
    return neck >= 0.25 * rim_dr


#: The trapped film's error |Δh̄(0)|/h̄(0) ≈ DIMPLE_ERROR Δr̄_c²/h̄_min on an interior spacing
#: Δr̄_c, held to DIMPLE_TARGET × rtol.
DIMPLE_ERROR = 0.068
DIMPLE_TARGET = 30.0


def _film_refinement(settings, error, target, film, most) -> float:
    """Δr̄/Δr̄_c, in [1, ``most``], for a film h̄ whose spatial error |Δh̄|/h̄ ≈ error·Δr̄_c²/h̄ on
    an interior spacing Δr̄_c is to stay below target × rtol: Δr̄ √(error/(target rtol h̄))."""
    dr = mesh_parameters(settings)[0]
    needed = dr * math.sqrt(error / (target * settings.rtol * film))
    return min(most, max(1.0, needed))


def _interior_refinement(settings, beta, t_end) -> float:
    """How much finer than Δr̄ the contact interior must be for the trapped film a run ends
    with: 1 for the default t̄ ≤ 5 run, up to ``Settings.contact_refinement``."""
    h_min = NECK_CONSTANT / math.sqrt(beta * t_end)
    return _film_refinement(settings, DIMPLE_ERROR, DIMPLE_TARGET, h_min,
                            settings.contact_refinement)


#: The neck's error |Δh̄_min|/h̄_min ≈ NECK_ERROR (Δr̄_rim/w)^NECK_ORDER, w ≈ h̄_min^{2/3} its
#: width, held to DIMPLE_TARGET × rtol.
NECK_ERROR = 0.12
NECK_ORDER = 2.35


def _rim_refinement(settings, beta, t_end) -> float:
    """How much finer than Δr̄ the contact's edge must be for the neck a run ends with: ~1 for
    the default t̄ ≤ 5 run, up to ``Settings.rim_refinement``."""
    dr = mesh_parameters(settings)[0]
    neck = (NECK_CONSTANT / math.sqrt(beta * t_end)) ** (2.0 / 3.0)
    cells = (NECK_ERROR / (DIMPLE_TARGET * settings.rtol)) ** (1.0 / NECK_ORDER)
    return min(settings.rim_refinement, max(1.0, dr * cells / neck))


def _contact_edge(settings, drive, z0, indenter=None) -> float | None:
    """The numeric ``Settings.contact_radius``, or with "auto" :func:`final_contact_radius`
    (None at the fine zone's end, where only widening the zone would help)."""
    if settings.contact_radius != "auto":
        return settings.contact_radius
    dr = mesh_parameters(settings)[0]
    rim = final_contact_radius(drive, float(z0), dr, indenter)
    return None if rim is None or rim >= 0.95 * settings.r_fine else rim


def _contact_refinement(settings, drive, z0, beta, t_end, indenter=None) -> float | None:
    """The radius ``Settings.contact_radius="auto"`` refines around for one run's film, or
    None (not "auto", no contact, or a neck no refined cell resolves)."""
    if settings.contact_radius != "auto":
        return None
    rim = _contact_edge(settings, drive, z0, indenter)
    dr = mesh_parameters(settings)[0]
    if rim is None or not _neck_resolvable(float(beta), t_end, dr / settings.rim_refinement):
        return None
    return rim


#: A collision's thinnest film h̄_c (:meth:`lubjax.FreeSphere.collision_film`), inside its
#: rebound contact of radius ā, has the error COLLISION_ERROR ā Δr̄_c²/h̄_c, held to
#: COLLISION_TARGET × rtol.
COLLISION_ERROR = 7.0
COLLISION_TARGET = 100.0


def _collision_refinement(settings, drive, z0, beta, rim) -> float:
    """How much finer than Δr̄ a collision's contact (radius ``rim``) must be for its thinnest
    film: 1 to ``Settings.rim_refinement``."""
    film = drive.collision_film(float(z0), beta)
    if film is None or rim <= 0:
        return 1.0
    return _film_refinement(settings, COLLISION_ERROR * rim, COLLISION_TARGET, film,
                            settings.rim_refinement)


#: Near dry the contact's spacing is at most max(Δr̄/contact_refinement, DRY_CONTACT_SLOPE Δr̄ r̄)
#: and its edge is refined DRY_RIM_REFINEMENT times (at most ``Settings.rim_refinement``): ×3
#: holds the force, the derivatives need ×6 (a force's derivative in the indentation is its
#: contact's radius, which a sharp edge between nodes misplaces by a fraction of a cell;
#: ``python -m benchmarks.studies.near_dry_edge`` measures it).
DRY_CONTACT_SLOPE = 2.0
DRY_RIM_REFINEMENT = 6.0
#: Near dry a run whose derivatives are taken has Δr̄ this many times finer (with the
#: tolerance's Δr̄; a given ``Settings.dr`` is kept): in a long hold at β ≳ 10⁸ the trapped
#: film's neck moves across the contact's nodes, and on the plain spacing each crossing puts a
#: spike of a few per cent into dF̄/dz̄0 however fine the steps (``Tolerance.for_tangents``
#: says what else such a run does).
DRY_DERIVATIVE_REFINEMENT = 1.4


def mesh_for(settings, *, drive, beta, z0, t_end, indenter=None,
             derivatives: bool = False, padded: bool = True) -> Mesh:
    """The mesh :func:`lubjax.relax` runs on for ``settings`` and one run: the tolerance's
    (``settings.mesh_parameters()``), refined for the contact the run ends in.

    With ``Settings.contact_radius="auto"`` (the default) the edge of the contact the drive
    ends in (:func:`final_contact_radius`) is refined for the neck a run ends with, and its
    inside for the trapped film: hardly at all for the default t̄ ≤ 5 run, up to
    ``rim_refinement`` and ``contact_refinement`` for long holds at large β. With a number,
    that radius is refined by the same factors; with None, nothing is. A free sphere's rebound
    contact is refined for the collision's thinnest film. Near dry
    (:func:`film_held_by_force`) the mesh serves the force: the axis to
    Δr̄/contact_refinement, the spacing growing as ``DRY_CONTACT_SLOPE`` Δr̄ r̄, the edge by
    ``DRY_RIM_REFINEMENT``, and with ``derivatives`` all of it ``DRY_DERIVATIVE_REFINEMENT``
    times finer. docs/design.md, "The mesh rule", gives the numbers.

    The refined mesh is then padded (:meth:`Mesh.padded`) to the next size of the family
    ⌈N₀·2^(k/8)⌉, N₀ that of the settings' mesh unrefined: at most 9 % more nodes, so that
    runs over a family of β, z̄0 and t̄_end share a few compiled programs instead of one per
    size (``padded=False``: not). The padding moves the force read at fixed times by ~1e-7 of
    its peak.

    :func:`lubjax.make_plan`, :func:`lubjax.sweep` and the fits share one mesh across a batch
    (``settings.mesh()``), so in long holds to thin films they can differ from ``relax``.

    Args:
        settings: a :class:`lubjax.Settings`.
        drive: a drive (``lubjax.Travel(history)``, ``Load``, ``Spring``, ``FreeSphere``;
            ``lubjax.as_drive(history)`` for a bare history).
        beta: β of the run (eq 8e), in ``BETA_RANGE``.
        z0: z̄0 = z0/d_c of the run (eq 8e), in ``Z0_RANGE``.
        t_end: its final time t̄ (units of t_c), in (0, 1e9].
        indenter: ``lubjax.Paraboloid()`` (None, the default: Hertz's contact radius) or
            ``lubjax.Sphere(d_c/R)`` (Sneddon's, smaller at the same depth).
        derivatives: whether the run's derivatives are taken (:func:`lubjax.relax` knows).
        padded: pad to a size of the family (default True); False: the refined mesh as it
            is, for a caller that compiles one program for all its runs anyway (a fit), where
            padding would only add nodes.

    Returns:
        Mesh: the mesh.

    Raises:
        TypeError: ``drive`` is not a drive.
        ValueError: β, z̄0 or ``t_end`` out of range (the message names it).
    """
    if not callable(getattr(drive, "final_depth", None)):
        raise TypeError(
            "drive must be a drive (lubjax.Travel, Load, Spring, FreeSphere; "
            f"lubjax.as_drive(history) for a history), got {type(drive).__name__}"
        )
    check_parameters(beta, z0)
    check_number("t_end", t_end, 0.0, T_END_MAX, lo_open=True)
    refined = _refined_mesh(settings, drive, float(beta), z0, float(t_end), indenter, derivatives)
    if not padded:
        return refined
    return refined.padded(padded_size(refined.size, settings_mesh(
        dataclasses.replace(settings, contact_radius=None)).size))


def _refined_mesh(settings, drive, beta, z0, t_end, indenter, derivatives) -> Mesh:
    """:func:`mesh_for`'s mesh before its padding."""
    near_dry = film_held_by_force(settings.film_error, beta)
    if drive.inertia:  # a free sphere: a collision, not a contact the run ends in
        rim = None
        if settings.contact_radius == "auto":
            rim = final_contact_radius(drive, float(z0), mesh_parameters(settings)[0], indenter)
        if rim is not None and not near_dry:
            # a rebound contact reaching the fine zone's end widens it: its film is thinnest there
            if rim >= 0.95 * settings.r_fine:
                settings = dataclasses.replace(settings, r_fine=1.25 * rim)
            collision = _collision_refinement(settings, drive, z0, beta, rim)
            return settings_mesh(settings, rim, collision, collision)
        return settings_mesh(settings, None, _interior_refinement(settings, beta, t_end),
                             _rim_refinement(settings, beta, t_end))
    if derivatives and near_dry and settings.dr is None:
        settings = dataclasses.replace(
            settings, dr=mesh_parameters(settings)[0] / DRY_DERIVATIVE_REFINEMENT)
    rim = _contact_edge(settings, drive, z0, indenter)
    if rim is not None and rim > 0 and near_dry:
        dr = mesh_parameters(settings)[0]
        return settings_mesh(settings, rim, settings.contact_refinement,
                             min(DRY_RIM_REFINEMENT, settings.rim_refinement),
                             contact_slope=DRY_CONTACT_SLOPE * dr)
    return settings_mesh(settings,
                         _contact_refinement(settings, drive, z0, beta, t_end, indenter),
                         _interior_refinement(settings, beta, t_end),
                         _rim_refinement(settings, beta, t_end))

"""Radial meshes: node positions r̄_0 = 0 < r̄_1 < ... < r̄_{N-1} = L̄.

The paper (Section 5) uses a uniform mesh on [0, 4] with p̄(L̄) = 0. That truncation drops the
r̄⁻⁴ pressure tail of the squeeze film: the fraction z̄/(z̄ + L̄²/2) of the force (6-20 % for
L̄ = 4, see docs/model.md). We instead default to a *graded* mesh: uniform and fine where the contact
lives, then geometrically coarser out to a large L̄, so the truncation costs a few dozen nodes.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class Mesh:
    """An immutable, hashable radial mesh (dimensionless r̄ = r/√(R d_c)).

    Attributes:
        nodes: tuple of node positions, strictly increasing, first node 0.
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
        return np.asarray(self.nodes, dtype=np.float64)

    @property
    def size(self) -> int:
        return len(self.nodes)

    @property
    def length(self) -> float:
        return self.nodes[-1]

    def coarsened(self) -> Mesh:
        """The nested mesh of every other node (the outer node kept): for error estimates."""
        nodes = self.nodes[::2]
        if nodes[-1] != self.nodes[-1]:
            nodes = (*nodes[:-1], self.nodes[-1])
        return Mesh(nodes)


def uniform_mesh(dr: float, length: float) -> Mesh:
    """Uniform mesh of spacing ``dr`` on [0, length] (the paper's: dr=0.01, length=4)."""
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
) -> Mesh:
    """Uniform spacing ``dr`` on [0, r_fine], then cells growing by ``growth`` up to ``length``;
    optionally refined to ``rim_dr`` around the radius ``rim`` and to ``contact_dr`` inside it.

    Why the rim: in a long hold with z̄0 < 1 the film drains through a neck at the Hertz
    contact's edge r̄ = a; near it h̄ ≈ h̄_min + c (r̄ - a)^{3/2}, so the neck is ~(h̄_min)^{2/3}
    wide: 0.01 at h̄_min = 10⁻³. A uniform dr = 0.014 under-resolves it; the flux through the
    neck (∝ h̄_min³) then sets the whole late drainage: h̄_min was 20 % off at t̄ = 10³ (β = 10³,
    z̄0 = 0.5), 1.3 % with rim_dr = dr/7 (measured against a run refined to 0.0005 there).
    ``rim = 0`` refines at the axis instead: a sphere that just touches (z̄0 = travel) presses a
    pressure spot that shrinks without bound as the film drains (half-width 0.014 at t̄ = 10³,
    β = 10³: one cell of dr = 0.014).

    Why the contact interior: inside a Hertz contact the trapped film h̄(0) ≈ 10⁻² is the small
    difference of z̄ + r̄²/2 and -w̄ ≈ 0.5, so 1 % of h̄(0) needs w̄ to 2·10⁻⁵ of itself: the
    O(dr²) error of the piecewise-linear pressure then asks for about half the spacing that the
    flow outside the contact needs.

    Args:
        dr: spacing in the fine zone, which must cover the Hertz contact radius √(1 - z̄0) ≤ 1 and
            the pressure rim around it.
        r_fine: outer edge of the fine zone.
        length: domain length L̄ (p̄ = 0 there). The dropped force fraction is ~ 4 z̄/L̄².
        growth: ratio of neighbouring cell sizes outside the fine zone (1 < growth ≤ 1.5).
        rim, rim_dr: inside the fine zone the spacing is min(dr, rim_dr + (RIM_GROWTH - 1)|r̄ -
            rim|) (then scaled so the zone still ends at a node).
        contact_dr: with ``rim``, the spacing on [0, rim] is at most contact_dr, and grows by
            RIM_GROWTH outside it: min(dr, contact_dr + (RIM_GROWTH - 1) max(r̄ - rim, 0)).
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
    if rim is not None:
        if not (0 <= rim < r_fine and rim_dr is not None and 0 < rim_dr <= dr):
            raise ValueError(
                f"need 0 <= rim < r_fine and 0 < rim_dr <= dr, got rim={rim}, rim_dr={rim_dr}"
            )
        inner = dr if contact_dr is None else contact_dr
        x, fine = 0.0, [0.0]
        while x < nodes[-1]:
            spread = RIM_GROWTH - 1.0
            x += min(dr, rim_dr + spread * abs(x - rim), inner + spread * max(x - rim, 0.0))
            fine.append(x)
        nodes = list(np.asarray(fine) * (nodes[-1] / fine[-1]))
    step = dr
    while True:
        step *= growth
        nxt = nodes[-1] + step
        if nxt >= length:
            # Merge a short last cell into its neighbour rather than leave a sliver.
            if length - nodes[-1] < 0.5 * step:
                nodes[-1] = length
            else:
                nodes.append(length)
            break
        nodes.append(nxt)
    return Mesh(tuple(float(x) for x in nodes))

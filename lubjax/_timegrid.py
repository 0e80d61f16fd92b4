"""Time grids for the stepper: small steps after every velocity jump, growing geometrically.

After a jump in indenter velocity the pressure adjusts on the fast time scale ~1/β (t_R = t_c/β,
Section 4.2), during loading the film evolves on the scale of t̄ ~ 1, and in the hold the trapped
film drains ever more slowly (self-similar in log t̄). One grid serves all three: in each segment
between breakpoints, steps start at ``dt_min`` and grow by ``growth`` per step up to a cap: ``dt``
inside [t_start, last breakpoint] (the loading), unbounded after it (the hold), so a hold to
t̄ = 10⁴ costs a few hundred steps. One grid serves any β ≤ ~0.1/dt_min, which is what lets a
``vmap`` sweep share it.
"""

from __future__ import annotations

import math

import numpy as np


def time_grid(
    t_end: float,
    *,
    dt: float = 2e-3,
    dt_min: float = 1e-6,
    growth: float = 1.08,
    t_start: float = 0.0,
    breakpoints: tuple[float, ...] = (1.0,),
    include: tuple[float, ...] = (),
    hold_dt_max: float | None = None,
) -> np.ndarray:
    """Node times t̄_0 = t_start < ... < t_end.

    Args:
        t_end: final time (> t_start).
        dt: largest step up to the last breakpoint (the loading phase).
        dt_min: first step after t_start and after each breakpoint.
        growth: ratio of consecutive steps while they grow (1 < growth ≤ 1.5; BDF2 stays
            zero-stable for ratios below 1 + √2).
        breakpoints: times where the indenter velocity jumps; each is a grid node.
        include: extra times that must be grid nodes (profile output times).
        hold_dt_max: cap on steps after the last breakpoint (default: none).
    """
    if not (math.isfinite(t_end) and t_end > t_start):
        raise ValueError(f"t_end must be finite and > t_start={t_start}, got {t_end}")
    if not (0 < dt_min <= dt):
        raise ValueError(f"need 0 < dt_min <= dt, got dt_min={dt_min}, dt={dt}")
    if not (1.0 < growth <= 1.5):
        raise ValueError(f"growth must be in (1, 1.5], got {growth}")
    inner = sorted({float(b) for b in breakpoints if t_start < b < t_end})
    last_break = inner[-1] if inner else t_start
    edges = [t_start, *inner, t_end]
    nodes = [t_start]
    for b in edges[1:]:
        cap = dt if b <= last_break else (hold_dt_max or math.inf)
        step = dt_min
        while nodes[-1] < b:
            s = min(step, cap)
            nxt = nodes[-1] + s
            if b - nxt < 0.3 * s:  # absorb a sliver into this step
                nxt = b
            nodes.append(nxt)
            step *= growth
    grid = np.asarray(nodes, dtype=np.float64)
    stops = np.asarray(sorted({float(x) for x in include if t_start < x < t_end}))
    if stops.size:
        # Insert the output times as nodes, dropping any node that would leave a sliver step.
        local = np.diff(grid)[np.clip(np.searchsorted(grid, stops) - 1, 0, grid.size - 2)]
        gap = np.min(np.abs(grid[:, None] - stops[None, :]) / (0.3 * local[None, :]), axis=1)
        keep = (gap >= 1.0) | np.isin(grid, [t_start, *inner, t_end])
        grid = np.union1d(grid[keep], stops)
    return grid

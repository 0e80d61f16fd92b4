"""Shared pieces of the benchmark methods: thread pinning, output grids, result bookkeeping and
the conservative finite-volume (FV) operators that the iterative/explicit/MOL methods share with
lubjax (same mesh arrays from ``lubjax.stepper.discretise``, same harmonic-Simpson face
mobility), so that those methods differ from lubjax only in how they step in time.

Every method module exposes ``run(beta, z0, t_out, **opts) -> (F_at_t_out, info)`` where
``info`` holds at least: wall_s (run time after compilation/setup), compile_s (jit compile and
one-off setup such as the influence matrix), finite, film_positive, converged, h_min, n_steps.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

import lubjax  # enables float64
from lubjax import _discretisation


def default_t_out(t_end: float = 5.0, every: float = 0.05) -> np.ndarray:
    n = int(round(t_end / every))
    return np.linspace(0.0, n * every, n + 1)


def travel(t):
    """Ramp-hold travel d̄(t̄) = min(t̄, 1) (eqs 8c,d)."""
    return np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)


def uniform_grid(t_end: float, dt: float, t_out=()) -> np.ndarray:
    """Uniform steps of ``dt`` (the last step absorbs a sliver); t̄ = 1 and ``t_out`` are nodes."""
    n = max(1, int(round(t_end / dt)))
    grid = np.linspace(0.0, t_end, n + 1)
    extra = [x for x in [1.0, *np.atleast_1d(t_out)] if 0 < x < t_end]
    if extra:
        grid = np.union1d(grid, np.round(extra, 12))
        # drop slivers created by the union
        keep = np.concatenate([[True], np.diff(grid) > 1e-9 * dt])
        grid = grid[keep]
    return grid


def growing_grid(t_end: float, dt: float, dt_min: float = 1e-6, growth: float = 1.1,
                 t_out=(), hold_dt_max: float | None = None,
                 breakpoints: tuple[float, ...] = (1.0,)) -> np.ndarray:
    """The comparison methods' own fixed geometric grid (lubjax itself is error-controlled now):
    in each segment between velocity jumps, steps start at ``dt_min`` and grow by ``growth`` up to
    ``dt`` in the loading and up to ``hold_dt_max`` (default: no cap) after the last jump; the
    jumps and ``t_out`` are nodes (a node that would leave a sliver < 0.3 step is dropped)."""
    if not (0 < dt_min <= dt and 1.0 < growth <= 1.5 and t_end > 0):
        raise ValueError(f"bad grid: t_end={t_end}, dt={dt}, dt_min={dt_min}, growth={growth}")
    inner = sorted({float(b) for b in breakpoints if 0.0 < b < t_end})
    last_break = inner[-1] if inner else 0.0
    nodes = [0.0]
    for edge in [*inner, t_end]:
        cap = dt if edge <= last_break else (hold_dt_max or np.inf)
        step = dt_min
        while nodes[-1] < edge:
            s = min(step, cap)
            nxt = nodes[-1] + s
            if edge - nxt < 0.3 * s:  # absorb a sliver into this step
                nxt = edge
            nodes.append(nxt)
            step *= growth
    grid = np.asarray(nodes)
    stops = np.unique(np.asarray([x for x in np.atleast_1d(t_out) if 0.0 < x < t_end], float))
    if stops.size:
        local = np.diff(grid)[np.clip(np.searchsorted(grid, stops) - 1, 0, grid.size - 2)]
        gap = np.min(np.abs(grid[:, None] - stops[None, :]) / (0.3 * local[None, :]), axis=1)
        keep = (gap >= 1.0) | np.isin(grid, [0.0, *inner, t_end])
        grid = np.union1d(grid[keep], stops)
    return grid


def at_outputs(t_grid: np.ndarray, values: np.ndarray, t_out: np.ndarray) -> np.ndarray:
    """Values at t_out: exact where t_out are nodes (they are, for all step methods here)."""
    idx = np.searchsorted(t_grid, t_out - 1e-12)
    idx = np.clip(idx, 0, len(t_grid) - 1)
    if np.all(np.abs(t_grid[idx] - t_out) < 1e-9):
        return values[idx]
    return np.interp(t_out, t_grid, values)


def make_info(*, wall_s, compile_s=0.0, force=None, film_min=None, converged=True, n_steps=0,
              **extra) -> dict:
    force = np.asarray(force, dtype=np.float64)
    film_min = np.asarray(film_min, dtype=np.float64)
    finite = bool(np.all(np.isfinite(force)) and np.all(np.isfinite(film_min)))
    h_min = float(np.nanmin(film_min)) if film_min.size and np.any(np.isfinite(film_min)) \
        else float("nan")
    info = dict(
        wall_s=float(wall_s),
        compile_s=float(compile_s),
        finite=finite,
        film_positive=bool(finite and np.all(film_min > 0)),
        force_nonneg=bool(finite and np.all(force >= -1e-12)),
        converged=bool(converged),
        h_min=h_min,
        n_steps=int(n_steps),
    )
    info["ok"] = info["finite"] and info["film_positive"] and info["converged"]
    info.update(extra)
    return info


# --- the shared FV operators (JAX), identical formulas to lubjax._discretisation ----------

def fv_mesh(kind: str = "graded", dr: float = 0.02, length: float = 100.0, r_fine: float = 1.6,
            growth: float = 1.04):
    mesh = lubjax.graded_mesh(dr, r_fine, length, growth) if kind == "graded" \
        else lubjax.uniform_mesh(dr, length)
    return lubjax.stepper.discretise(mesh)


def film(disc, z, p):
    """h̄ = z̄ + r̄²/2 + Ŵp̄ at all nodes."""
    return z + 0.5 * disc.r**2 + disc.influence @ p


def face_conductance(disc, h, z):
    """lubjax's face conductances g ≈ r̄h̄³/Δr̄ (``lubjax._discretisation.face_conductance``) of
    the film h at the nodes, gap z (the midpoint film as lubjax takes it)."""
    elastic = h - z - 0.5 * disc.r**2
    h_mid = z + 0.5 * disc.face_r**2 + 0.5 * (elastic[:-1] + elastic[1:])
    return _discretisation.face_conductance(disc, h, h_mid)


def flux_divergence(disc, beta, h, z, p):
    """(T p)_i = g_{i+1/2}(p_{i+1}-p_i) - g_{i-1/2}(p_i-p_{i-1}), g = β conductance (all nodes)."""
    g = beta * face_conductance(disc, h, z)
    q = g * (p[1:] - p[:-1])  # flux through each face (outward positive when p rises outward)
    return jnp.concatenate([q, jnp.zeros(1, q.dtype)]) - jnp.concatenate(
        [jnp.zeros(1, q.dtype), q])


def tridiag_parts(disc, beta, h, z):
    """Sub/diag/super of -T restricted to the unknowns p_0..p_{N-2} (p_{N-1} = 0)."""
    g = beta * face_conductance(disc, h, z)
    n = disc.r.shape[0] - 1
    diag = g[:n] + jnp.concatenate([jnp.zeros(1, g.dtype), g[: n - 1]])
    lower = jnp.concatenate([jnp.zeros(1, g.dtype), -g[: n - 1]])
    upper = jnp.concatenate([-g[: n - 1], jnp.zeros(1, g.dtype)])
    return lower, diag, upper


def timed_compile(fn, *args):
    """AOT-compile a jitted function; returns (compiled, seconds)."""
    import time

    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    return compiled, time.perf_counter() - start


__all__ = [
    "at_outputs", "default_t_out", "face_conductance", "film", "flux_divergence", "fv_mesh",
    "growing_grid", "jnp", "make_info", "timed_compile", "travel",
    "tridiag_parts", "uniform_grid",
]


def fv_setup(t_out, *, mesh="graded", dr=0.02, length=None, r_fine=1.6, mesh_growth=1.04,
             steps="fixed", dt=1e-3, dt_min=1e-6, growth=1.1):
    """Mesh (lubjax's graded default, or uniform with the paper's L̄ = 4) and time grid
    ("fixed" uniform Δt̄, or "grow"/"cap" as lubjax) for the FV methods; t_out are nodes."""
    t_out = np.asarray(t_out, dtype=np.float64)
    t_end = float(t_out[-1])
    if mesh == "graded":
        disc = fv_mesh("graded", dr, 100.0 if length is None else length, r_fine, mesh_growth)
    else:
        disc = fv_mesh("uniform", dr, 4.0 if length is None else length)
    if steps == "fixed":
        t = uniform_grid(t_end, dt, t_out)
    else:
        t = growing_grid(t_end, dt, dt_min, growth, t_out=t_out,
                         hold_dt_max=dt if steps == "cap" else None)
    return disc, t


_COMPILED: dict = {}


def run_iterative_rollout(key, rollout, disc, beta, z, dt):
    """Compile ``rollout(disc, beta, z, dt)`` once per ``key`` (compile time reported apart) and
    run it. The rollout returns ((force, h_min, iterations, converged) per step, initial h_min).

    Returns force and h_min with the initial node prepended, iterations, converged, wall and
    compile seconds.
    """
    compile_s = 0.0
    if key not in _COMPILED:
        start = time.perf_counter()
        _COMPILED[key] = jax.jit(rollout).lower(disc, 1.0, z, dt).compile()
        compile_s = time.perf_counter() - start
    start = time.perf_counter()
    (force, hmin, iters, conv), h0 = jax.block_until_ready(
        _COMPILED[key](disc, float(beta), z, dt))
    wall = time.perf_counter() - start
    force = np.concatenate([[0.0], np.asarray(force)])
    hmin = np.concatenate([[float(h0)], np.asarray(hmin)])
    return force, hmin, np.asarray(iters), np.asarray(conv), wall, compile_s

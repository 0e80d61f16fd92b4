r"""The spatial discretisation (paper Section 5, eqs 17-22): per-mesh arrays, the film, and the
face conductances of Reynolds' equation in conservative, finite-volume form on a graded mesh.

Node i owns the cell [r̄_{i-1/2}, r̄_{i+1/2}] (midpoints; r̄_{-1/2} = 0) of area measure
A_i = (r̄²_{i+1/2} - r̄²_{i-1/2})/2:

    A_i dh̄_i/dt̄ = β g_{i+1/2} (p̄_{i+1} - p̄_i) - β g_{i-1/2} (p̄_i - p̄_{i-1}),

with the face conductances g ≈ r̄ h̄³/Δr̄ (:func:`face_conductance`) and h̄ = z̄ + s(r̄) + Ŵ p̄
(eqs 8a, 21), s the indenter's rigid profile. The face at r̄ = 0 carries no flux (eq 22a); the
outer node carries p̄ = 0 (eq 22b). Departs from the paper's expanded form (17a, c): second
order on any mesh, the film volume changing exactly by the boundary flux.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._influence import force_weights, influence_matrix
from ._mesh import Mesh
from ._shape import Paraboloid, as_indenter
from ._substrate import HalfSpace, as_substrate

#: Names the spatial discretisation, for caches of computed runs (benchmarks/accuracy.py).
DISCRETISATION = "psi-weighted hats, radius-weighted conductance"


class Discretisation(NamedTuple):
    """Mesh-dependent arrays (:func:`discretise`), a pytree; lengths in units of √(R d_c).

    Attributes:
        r: the nodes r̄_i, shape (N,).
        cell_area: A_i = (r̄²_{i+1/2} - r̄²_{i-1/2})/2, each node's cell's area measure, (N,).
        face_r: r̄_{i+1/2}, the faces between nodes, (N-1,).
        face_gap: r̄_{i+1} - r̄_i, (N-1,).
        influence: Ŵ, the influence matrix (eq 21), (N, N).
        area_influence: (A Ŵ)_ij restricted to the unknowns i, j < N-1, (N-1, N-1).
        force_weights: c, with F̄ = c·p̄ (eq 11b), (N,).
        profile: s(r̄_i), the indenter's rigid gap profile at the nodes (units of d_c), (N,).
        face_profile: s(r̄_{i+1/2}) at the faces, (N-1,).
    """

    r: jax.Array
    cell_area: jax.Array
    face_r: jax.Array
    face_gap: jax.Array
    influence: jax.Array
    area_influence: jax.Array
    force_weights: jax.Array
    profile: jax.Array
    face_profile: jax.Array


def discretise(mesh: Mesh, substrate=None, indenter=None) -> Discretisation:
    """All per-mesh arrays for a substrate's geometry and an indenter's shape; cached, so the
    influence matrix is built once per (mesh, elastic substrate).

    Args:
        mesh: the :class:`lubjax.Mesh`.
        substrate: ``lubjax.HalfSpace()`` (None, the default), a ``Layer`` or a
            ``Viscoelastic`` (its elastic geometry).
        indenter: ``lubjax.Paraboloid()`` (None, the default) or ``lubjax.Sphere(d_c/R)``; a
            traced sphere (under ``jit``/``vmap``/``grad``) gives traced profiles.

    Returns:
        Discretisation: float64 arrays on the default device.

    Raises:
        TypeError: ``substrate`` is not a substrate, or ``indenter`` not a shape.
    """
    disc = _discretise(mesh, as_substrate(substrate).elastic)
    indenter = as_indenter(indenter)
    if isinstance(indenter, Paraboloid):
        return disc
    r, face = mesh.r, 0.5 * (mesh.r[1:] + mesh.r[:-1])
    profiles = (indenter.profile(r), indenter.profile(face))
    if isinstance(profiles[0], np.ndarray):
        profiles = tuple(jax.device_put(p) for p in profiles)
    return disc._replace(profile=profiles[0], face_profile=profiles[1])


@functools.lru_cache(maxsize=32)
def _discretise(mesh: Mesh, elastic) -> Discretisation:
    r = mesh.r
    face = 0.5 * (r[1:] + r[:-1])
    outer = np.concatenate([face, [r[-1]]])
    inner = np.concatenate([[0.0], face])
    area = 0.5 * (outer**2 - inner**2)
    w = influence_matrix(mesh) if isinstance(elastic, HalfSpace) else elastic.influence(mesh)
    shape = Paraboloid()
    arrays = (r, area, face, np.diff(r), w, area[:-1, None] * w[:-1, :-1], force_weights(mesh),
              shape.profile(r), shape.profile(face))
    # device_put, not jnp.asarray: outside jit, jnp.asarray compiles a copy per new shape.
    # Concrete even when first asked for under jit (relax traced): the cache outlives the trace.
    with jax.ensure_compile_time_eval():
        return Discretisation(*(jax.device_put(np.asarray(a, np.float64)) for a in arrays))


def film_thickness(disc: Discretisation, z, pressure):
    """The film thickness h̄ = z̄ + s(r̄) - w̄ with w̄ = -Ŵp̄ (eqs 8a, 21), s = ``disc.profile``.

    Args:
        disc: the :class:`Discretisation`.
        z: z̄, the sphere's gap (units of d_c); a scalar.
        pressure: p̄ at the nodes (units of (2E*/π)√(d_c/R)), shape (N,).

    Returns:
        h̄ at the nodes (units of d_c), shape (N,).
    """
    return z + disc.profile + disc.influence @ pressure


def displacement(disc: Discretisation, pressure):
    """The surface displacement w̄ = -Ŵp̄ (eq 21).

    Args:
        disc: the :class:`Discretisation`.
        pressure: p̄ at the nodes (units of (2E*/π)√(d_c/R)), shape (N,).

    Returns:
        w̄ at the nodes (units of d_c; ≤ 0 under a positive pressure), shape (N,).
    """
    return -disc.influence @ pressure


def elastic_part(disc: Discretisation, film, z):
    """Ŵp̄ = -w̄ at the nodes, from the film: h̄ less its rigid part z̄ + s(r̄) (eq 21)."""
    return film - z - disc.profile


#: How far a node's fluxes reach in the films: its faces' midpoint films take nodes i-2..i+2.
FILM_STENCIL = 2


def film_at_midpoints(disc: Discretisation, film, z):
    """h̄ at the cell midpoints: the rigid part z̄ + s(r̄) exactly, the elastic part e = Ŵp̄
    interpolated with its curvature,

        e(r̄_{i+1/2}) ≈ (e_i + e_{i+1})/2 - (Δr̄²/8) (e''_i + e''_{i+1})/2,

    e'' the three-point second difference at each node (e' = 0 at the axis; the outer node takes
    its neighbour's). On a uniform mesh this is the four-point cubic (-1, 9, 9, -1)/16.

    Departs from linear interpolation of e: inside a contact e curves with the indenter
    (e'' ≈ -1/R̄), which the straight chord misses by Δr̄²/8 ~ 10⁻⁵ — against near-dry films of
    10⁻⁹, so the midpoint film went negative, the conductance took negative 1/h̄³ terms and the
    tangent of the run grew without bound. With the curvature the midpoint film in a contact is
    the cubic through the nodal films (exact for a paraboloid's rigid part); what is still
    negative, at a contact's edge, :func:`_smooth_floor` holds.
    """
    elastic = elastic_part(disc, film, z)
    slope = jnp.diff(elastic) / disc.face_gap
    spacing = 0.5 * (disc.face_gap[1:] + disc.face_gap[:-1])
    interior = jnp.diff(slope) / spacing
    axis = 2.0 * slope[:1] / disc.face_gap[:1]  # mirror node e_{-1} = e_1
    curvature = jnp.concatenate([axis, interior, interior[-1:]])
    mean_curvature = 0.5 * (curvature[:-1] + curvature[1:])
    chord = 0.5 * (elastic[:-1] + elastic[1:])
    interpolated = z + disc.face_profile + chord - disc.face_gap**2 / 8.0 * mean_curvature
    return _smooth_floor(interpolated, film[:-1], film[1:])


#: The midpoint film's floor b, as a fraction of the nodal films' harmonic mean, and the half
#: width, as a fraction of b, over which the film passes onto it.
MIDPOINT_FLOOR = 0.2
FLOOR_BLEND = 0.1


def _smooth_floor(h_mid, h_left, h_right):
    """h̄_m held above b = ``MIDPOINT_FLOOR`` × the harmonic mean of the nodes' films, smoothly:
    max(h̄_m, b) with its corner rounded by the parabola b + (h̄_m - b + w)²/(4w) on
    |h̄_m - b| < w = ``FLOOR_BLEND`` b, which meets both with a continuous slope.

    Departs from the paper (which has no midpoint): at a near-dry contact's edge the discrete
    pressure can make the midpoint film negative (a node pins the contact, the cell between
    interpenetrates) even with the curvature. A resolved film (h̄_m ≥ 0.9 min(h̄_i, h̄_{i+1}),
    above b + w ≤ 0.44 min) passes bit for bit; the continuous slope keeps a fit's model free
    of the kink of a plain max().
    """
    floor = MIDPOINT_FLOOR * 2.0 * h_left * h_right / (h_left + h_right)
    width = FLOOR_BLEND * floor
    corner = floor + (h_mid - floor + width) ** 2 / (4.0 * width)
    return jnp.where(h_mid >= floor + width, h_mid, jnp.where(h_mid <= floor - width, floor,
                                                              corner))


def extrapolate_film(h, h_prev, omega):
    """Geometric extrapolation h* = h (h/h_prev)^ω; falls back to h where either is not positive."""
    positive = (h > 0) & (h_prev > 0)
    ratio = jnp.where(positive, h / jnp.where(positive, h_prev, 1.0), 1.0)
    return h * ratio**omega


def face_conductance(disc: Discretisation, h, h_mid):
    """Conductance of each cell [r̄_i, r̄_{i+1}] between its nodes (the flux through the face
    r̄_f = r̄_{i+1/2} is β g (p̄_{i+1} - p̄_i), per unit 2π), from the film h̄ at the nodes and
    h̄_m at the midpoint:

        1/g = (Δr̄/r̄_f²) ∫ r̄ dr̄/h̄³ / Δr̄  by Simpson's rule,
            = (Δr̄/r̄_f²) (r̄_i/h̄_i³ + 4 r̄_f/h̄_m³ + r̄_{i+1}/h̄_{i+1}³)/6.

    Exact for the flux of a uniform source, Q ∝ r̄² (the squeeze film's, and any flow's near
    the axis); a face closes as either node's film closes (docs/design.md, "Departures").
    """
    r = disc.r
    mean = (r[:-1] / h[:-1] ** 3 + 4.0 * disc.face_r / h_mid**3 + r[1:] / h[1:] ** 3) / 6.0
    return disc.face_r**2 / (disc.face_gap * mean)


def face_conductance_extrapolated(disc: Discretisation, film, film_prev, gap, gap_prev, omega):
    """:func:`face_conductance` of the film extrapolated to the new level (eq 19 lags it; BDF2
    extrapolates it geometrically, :func:`extrapolate_film`)."""
    return conductance_of_extrapolated(
        disc, lambda h, h1: extrapolate_film(h, h1, omega), ((film, gap), (film_prev, gap_prev))
    )


def conductance_of_extrapolated(disc: Discretisation, extrapolate, levels):
    """:func:`face_conductance` of ``extrapolate`` applied to the nodal films and, alike, to the
    midpoint films of ``levels`` ((film, gap) pairs, newest first)."""
    h = extrapolate(*(film for film, _ in levels))
    h_mid = extrapolate(*(film_at_midpoints(disc, film, gap) for film, gap in levels))
    return face_conductance(disc, h, h_mid)


def flux_divergence(g, p):
    """The flux operator: (T p̄)_i = g_{i+1/2}(p̄_{i+1} - p̄_i) - g_{i-1/2}(p̄_i - p̄_{i-1})."""
    flux = g * (p[1:] - p[:-1])
    zero = jnp.zeros(1, p.dtype)
    return jnp.concatenate([flux, zero]) - jnp.concatenate([zero, flux])

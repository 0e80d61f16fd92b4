r"""From SI parameters to the measured response at the sample times of a trace, and its Jacobian.

One model for every experiment: a **drive** (what the instrument prescribes) and a **substrate**
(what the sphere presses into) go to the same error-controlled ``lubjax.stepper.rollout``:

* ``"travel"`` (position control): input ``displacement_m``, response ``force_N``,
  ``lubjax.Travel(d̄(t̄))``;
* ``"spring"`` (position control through a load cell of stiffness k): input
  ``displacement_m`` (the stage), response ``force_N``, ``lubjax.Spring(K̄, d̄(t̄))``;
* ``"force"`` (load control, creep): input ``force_N``, response ``displacement_m``,
  ``lubjax.Load(F̄_end, F(t̄)/F_end)``.

Substrates: the half-space (default), a layer of known thickness H on a rigid base
(``ModelSpec.layer``), either of them viscoelastic (``ModelSpec.viscoelastic``: a standard
linear solid whose E0/E∞ and τ are fitted; E* is then the relaxed modulus E*∞). Indenters: the
paraboloid (default) or the sphere's true profile (``ModelSpec.indenter``). Scales taken from
the data (not from the user): :mod:`fitting._scales`.

With the speed d_c/t_c in eq 8e, β = E* d_c^{3/2} t_c/(6π η R^{3/2}) and z̄0 = z0/d_c for every
drive (the creep test of ``lubjax.CreepTest`` uses the same β with its own d_c). The measured
input u(t)/u_end (not an ideal ramp) is the solver's history, monotone-cubic interpolated
wherever the stepper needs it. The model of sample k is

    force response:         y_k = (2 E* d_c^{3/2} √R / π) · F̄(t̄_k) + b      (eq 11b)
    displacement response:  y_k = d_c (z̄0 - z̄(t̄_k)) + b                  (approach since rest)

with F̄ and z̄ the rollout read at t̄_k by the stepper's own interpolant (the steps do not depend
on the sample times), b a constant offset of the response channel. The drive's numbers follow
from E*: K̄ = π k/(2E*√(R d_c)) and the load F̄_end = F_end/F_s(E*), F_s = 2E* d_c^{3/2}√R/π.

Parameters θ (all of order one or logarithms): ln E*, ln η, ln z0, [ln(E0/E∞ - 1), ln τ], b/y_u
(y_u: the peak of the response). Residuals r_k = w_k (y_k(θ) - y_k^data)/σ with w_k ∈ {0, 1}
(0 pads traces of different lengths to a common shape so that they ``vmap`` together) and σ the
trace's noise level (:func:`noise_level`), so that Σr² is a χ² and traces of different noise
weigh correctly in a joint fit.

The Jacobian ∂r/∂θ is taken in forward mode through the stepper's ``while_loop`` (one
``jax.jvp`` per number the stepper sees, ``vmap``-ed: ln β and ln z0 for a prescribed travel;
E* and η enter the stepper only through β): the tangents ride along with the factorisation, so
the Jacobian costs about one run, and memory does not grow with the number of steps.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import lubjax
from lubjax._fitting_api import checks as _checks
from lubjax._fitting_api import compiler as _compiler
from lubjax._fitting_api import sharding as _sharding

from ._scales import Scales, channels, drive_unit, history, noise_level
from ._trace import DRIVES, Trace, check_scales

FIT_SETTINGS = lubjax.Settings(rtol=3e-4, force_floor=1e-5, max_steps=5000)
"""The accuracy of the model inside fits: ``lubjax.Settings(rtol=3e-4, force_floor=1e-5,
max_steps=5000)``. rtol = 3e-4 keeps the model's error at the true parameters of the bundled
traces to 2e-3 of the peak (rms 1.5e-4); the force is held to rtol only down to 1e-5 of its
peak (a load cell's noise is ≥ 1e-3 of it); a bundled trace takes about 300 of the 5000
attempts. The film error is relax's default "auto": the force norm near dry (β ≥ 10⁵), where
the relative norm would hold a film far thinner than anything the force sees to itself in
thousands of steps; the Jacobian's runs hold that film tighter (a derivative's film cap,
``lubjax.stepper.Tolerance.for_tangents``), so its tangents are sound there (docs/guide/fitting.md,
near-dry contacts). The model's remaining error at the optimum is estimated and folded into
the reported errors."""


@dataclasses.dataclass(frozen=True)
class ModelSpec:
    """What is fitted: the drive, the substrate and the offset (static: one per compiled model).

    Args:
        drive: "travel" (prescribed travel, the default), "spring" (travel through a load cell
            of stiffness ``# stiffness_N_m:``) or "force" (load control).
        layer: None (half-space, the default) or (H [m] > 0, ν in (-1, 0.5], "bonded" |
            "frictionless"): a layer of known thickness on a rigid base.
        viscoelastic: fit a standard linear solid (E0/E∞, τ) instead of an elastic solid
            (default False).
        fit_offset: fit a constant offset of the response channel (default True).
        indenter: "paraboloid" (default: travel ≤ 0.2 R) or "sphere", the sphere's true
            profile for deep indentation (``lubjax.Sphere(d_c/R)`` per trace).

    Raises:
        ValueError: an unknown ``drive`` or ``indenter``, or a ``layer`` not (thickness,
            Poisson's ratio, base) in range.
    """

    drive: str = "travel"
    layer: tuple | None = None
    viscoelastic: bool = False
    fit_offset: bool = True
    indenter: str = "paraboloid"

    def __post_init__(self):
        if self.drive not in DRIVES:
            raise ValueError(f"drive must be one of {', '.join(DRIVES)}, got {self.drive!r}")
        _checks.check_choice("indenter", self.indenter, _checks.INDENTERS)
        if self.layer is not None:
            try:
                h, nu, base = self.layer
                h, nu = float(h), float(nu)
            except (TypeError, ValueError):
                raise ValueError(
                    f"layer must be (thickness_m, poisson, base), got {self.layer!r}"
                ) from None
            _checks.check_quantity("layer thickness", h, "metres")
            _checks.check_poisson("layer Poisson ratio", nu)
            _checks.check_layer_base("layer base", base)
            object.__setattr__(self, "layer", (h, nu, base))

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names, in the order of θ."""
        extra = ("stiffening", "relaxation_time") if self.viscoelastic else ()
        return ("E_star", "viscosity", "z0", *extra, "offset")

    @property
    def response(self) -> str:
        """The fitted channel: "force" or "displacement"."""
        return "displacement" if self.drive == "force" else "force"

    @property
    def active(self) -> np.ndarray:
        """Which θ components are fitted (the offset may be held at 0)."""
        return np.array([n != "offset" or self.fit_offset for n in self.names])

    def substrate_label(self) -> str:
        """The substrate in words, for reports.

        Returns:
            E.g. "elastic half-space" or "viscoelastic (standard linear solid) layer H = ...".
        """
        geometry = "half-space" if self.layer is None else (
            f"layer H = {self.layer[0]:.4g} m (nu = {self.layer[1]:g}, {self.layer[2]} base)"
        )
        return ("viscoelastic (standard linear solid) " if self.viscoelastic else "elastic ") + (
            geometry
        )


#: Physical value x from its θ component, and dx/dθ (for standard errors by the delta method).
def to_physical(name: str, theta_i: float, data_unit: float = 1.0) -> tuple[float, float]:
    if name == "offset":
        return theta_i * data_unit, data_unit
    if name == "stiffening":
        e = math.exp(theta_i)
        return 1.0 + e, e
    x = math.exp(theta_i)
    return x, x


def to_theta(name: str, value: float, data_unit: float = 1.0) -> float:
    if name == "offset":
        return value / data_unit
    if name == "stiffening":
        return math.log(max(value - 1.0, 1e-6))
    return math.log(value)


class TraceData(NamedTuple):
    """The arrays one trace contributes to the model (a pytree; stack them to ``vmap``;
    :func:`trace_data`).

    Attributes:
        history: the measured input u(t̄)/u_end (a ``lubjax.SampledTravel``), padded to a
            common sample count.
        t_end: t̄ of the last sample (units of t_c).
        t_data: t̄ of the samples.
        response: the measured response [N or m].
        weight: w_k, 1 for samples, 0 for padding.
        log_beta_unit: ln[d_c^{3/2} t_c/(6π R^{3/2})]: ln β = ln E* - ln η + this (eq 8e).
        indent: d_c [m].
        time_scale: t_c [s].
        force_scale_unit: 2 d_c^{3/2} √R/π [m²]: F = E* · this · F̄ (eq 11b).
        response_unit: y_u, the offset's unit [N or m].
        noise: σ, the residuals' unit [N or m].
        drive_unit: the load F_end/``force_scale_unit`` or the spring's π k/(2√(R d_c)) [Pa];
            ÷ E* gives the drive's dimensionless number.
        disc: the trace's own discretisation (a layer's influence matrix, the sphere's
            profile for its d_c/R), or None: the solver's.
    """

    history: lubjax.SampledTravel
    t_end: jax.Array
    t_data: jax.Array
    response: jax.Array
    weight: jax.Array
    log_beta_unit: jax.Array
    indent: jax.Array
    time_scale: jax.Array
    force_scale_unit: jax.Array
    response_unit: jax.Array
    noise: jax.Array
    drive_unit: jax.Array
    disc: lubjax.stepper.Discretisation | None


class Solver(NamedTuple):
    """What every trace of a batch shares: the mesh arrays and the tolerance (its numbers are
    leaves, its order and step budget static; :func:`make_solver`).

    Attributes:
        disc: the :class:`lubjax.stepper.Discretisation` of the settings' mesh.
        tol: the :class:`lubjax.stepper.Tolerance`.
    """

    disc: lubjax.stepper.Discretisation
    tol: lubjax.stepper.Tolerance


def make_solver(settings=None) -> Solver:
    """The mesh arrays (cached per mesh) and the tolerance of some settings.

    Args:
        settings: a ``lubjax.Settings``; None (default): ``FIT_SETTINGS``.

    Returns:
        Solver: the shared mesh arrays and tolerance.
    """
    settings = FIT_SETTINGS if settings is None else settings
    return Solver(lubjax.stepper.discretise(settings.mesh()), settings.tolerance())


def _pad_history(hist: lubjax.SampledTravel, n: int) -> lubjax.SampledTravel:
    """Extend to n samples: times continue past the end, the input is held (it is anyway)."""
    extra = n - hist.t.size
    t = np.concatenate([hist.t, hist.t[-1] + 1.0 + np.arange(extra)])
    d = np.concatenate([hist.travel_samples, np.full(extra, hist.travel_samples[-1])])
    return lubjax.SampledTravel(t, d, breakpoints=hist.breakpoints)


def layer_substrate(spec: ModelSpec, scales: Scales):
    """The ``lubjax.Layer`` of a spec with a layer: H̄ = H/√(R d_c) of this trace."""
    h, nu, base = spec.layer
    return lubjax.Layer(lubjax.layer_thickness_bar(h, scales.radius, scales.indent), nu, base)


def trace_data(
    trace: Trace,
    scales: Scales,
    spec: ModelSpec,
    mesh: lubjax.Mesh | None = None,
    n_pad: int | None = None,
    n_history: int | None = None,
) -> TraceData:
    """The arrays one trace contributes to the model.

    Args:
        trace: the :class:`Trace`.
        scales: its :class:`Scales`.
        spec: the :class:`ModelSpec`.
        mesh: the solver's ``lubjax.Mesh``, needed for a layer's influence matrix; None
            (default): ``FIT_SETTINGS.mesh()``.
        n_pad: pad the samples to this count with zero weight (≥ the trace's), so traces of
            different lengths stack; None (default): no padding.
        n_history: pad the input history to this many samples likewise; None: no padding.

    Returns:
        TraceData: the trace's arrays.
    """
    n = trace.time.size
    n_pad = n if n_pad is None else n_pad
    pad = n_pad - n
    tb = (trace.time - scales.t_on) / scales.time_scale
    hist = history(trace, scales, spec.drive)
    hist = _pad_history(hist, hist.t.size if n_history is None else n_history)
    response = channels(trace, spec.drive)[1]
    R, dc, tc = scales.radius, scales.indent, scales.time_scale
    fsu = scales.force_scale(1.0)
    check_scales(trace, spec.indenter)
    shape = lubjax.Sphere(dc / R) if spec.indenter == "sphere" else None
    disc = None if spec.layer is None and shape is None else _layer_disc(
        FIT_SETTINGS.mesh() if mesh is None else mesh,
        None if spec.layer is None else layer_substrate(spec, scales), shape)
    sigma = max(noise_level(response), 1e-6 * scales.response_unit)
    return TraceData(
        history=hist,
        t_end=jnp.asarray(float(tb[-1])),
        t_data=jnp.asarray(np.pad(tb, (0, pad), mode="edge")),
        response=jnp.asarray(np.pad(response, (0, pad), mode="edge")),
        weight=jnp.asarray(np.pad(np.ones(n), (0, pad))),
        log_beta_unit=jnp.asarray(math.log(dc**1.5 * tc / (6 * math.pi * R**1.5))),
        indent=jnp.asarray(dc),
        time_scale=jnp.asarray(tc),
        force_scale_unit=jnp.asarray(fsu),
        response_unit=jnp.asarray(scales.response_unit),
        noise=jnp.asarray(sigma),
        drive_unit=jnp.asarray(drive_unit(trace, scales, spec.drive)),
        disc=disc,
    )


def _layer_disc(mesh, layer, shape=None):
    try:
        return lubjax.stepper.discretise(mesh, layer, shape)
    except ImportError as exc:  # lubjax/_layer.py (the layer's influence matrix) is missing
        raise RuntimeError(f"the layer substrate needs the layer's influence matrix "
                           f"(lubjax/_layer.py), which this installation lacks ({exc})") from None


def make_drive(drive: str, unit, history, E_star):
    """The lubjax drive of a trace: ``drive`` (one of ``DRIVES``), its
    :func:`drive_unit`, its input ``history`` and the modulus E* [Pa]."""
    if drive == "force":
        return lubjax.Load(unit / E_star, history)
    if drive == "spring":
        return lubjax.Spring(unit / E_star, history)
    return lubjax.Travel(history)


def _drive(spec: ModelSpec, data: TraceData, E_star):
    return make_drive(spec.drive, data.drive_unit, data.history, E_star)


def _substrate(spec: ModelSpec, u, data: TraceData):
    """The substrate as the stepper sees it: a creep compliance (the geometry, half-space or
    layer, is the influence matrix in the discretisation, lubjax/_substrate.py). A layer's
    thickness H̄ differs per trace and is static in ``lubjax.Layer``, so traces of one batch
    carry their own influence matrix (``data.disc``) and share the half-space's compliance
    type here: J ≡ 1, or the standard linear solid (its two parameters the last of ``u``)."""
    if not spec.viscoelastic:
        return lubjax.HalfSpace()
    stiffening = 1.0 + jnp.exp(u[-2])
    tau_bar = jnp.exp(u[-1]) / data.time_scale
    return lubjax.Viscoelastic.standard_linear_solid(stiffening, tau_bar)


def solver_inputs(theta, data: TraceData, spec: ModelSpec):
    """u: what of θ the stepper sees, as one vector: ln β = ln E* - ln η + const, ln z0, then
    ln E* where the drive carries it (load or spring: K̄, F̄ ∝ 1/E*), then the viscoelastic
    ln(E0/E∞ - 1), ln τ. E* and η reach the stepper only through β (travel drive), so the
    Jacobian needs 2 tangents through the stepper, not one per parameter
    (:func:`residuals_and_jacobian`)."""
    parts = [theta[0] - theta[1] + data.log_beta_unit, theta[2]]
    if spec.drive != "travel":
        parts.append(theta[0])
    if spec.viscoelastic:
        parts += [theta[3], theta[4]]
    return jnp.stack(parts)


def _stepper_output(u, data: TraceData, solver: Solver, spec: ModelSpec):
    """The stepper's channel at the samples (F̄, or the gap z̄ under load control) and the
    thinnest film min h̄ over the run (must stay > 0; -inf when the run did not reach its last
    sample), from ``u`` (:func:`solver_inputs`)."""
    beta = jnp.exp(u[0])
    z0_bar = jnp.exp(u[1]) / data.indent
    E_star = jnp.exp(u[2]) if spec.drive != "travel" else None
    disc = solver.disc if data.disc is None else data.disc
    traj = lubjax.stepper.rollout(
        disc, beta, z0_bar, _drive(spec, data, E_star), data.t_end, solver.tol,
        substrate=_substrate(spec, u, data),
    )
    channel = "force" if spec.response == "force" else "gap"
    y = lubjax.stepper.evaluate(traj.steps, data.t_data, channel)
    film = jnp.min(jnp.where(traj.steps.accepted, traj.steps.film_min, jnp.inf))
    return y, jnp.where(traj.finished, film, -jnp.inf)


def _response(theta, channel, data: TraceData, spec: ModelSpec):
    """The model response [N or m] from the stepper's channel: F = E* F_s,unit F̄, or the
    approach d = z0 - d_c z̄; plus the offset."""
    if spec.response == "force":
        y = jnp.exp(theta[0]) * data.force_scale_unit * channel
    else:
        y = data.indent * (jnp.exp(theta[2]) / data.indent - channel)
    return y + theta[-1] * data.response_unit


def predict(theta, data: TraceData, solver: Solver, spec: ModelSpec):
    """The model's response at the samples: y_k = F_s F̄(t̄_k) + b for a force response (eq 11b),
    y_k = d_c (z̄0 - z̄(t̄_k)) + b for a displacement response (``fitting._model``).

    Args:
        theta: θ = (ln E*, ln η, ln z0, [ln(E0/E∞ - 1), ln τ], b/y_u), a 1-D array (SI inside
            the logarithms).
        data: the trace's :class:`TraceData`.
        solver: the :class:`Solver`.
        spec: the :class:`ModelSpec`.

    Returns:
        (y, h̄_min): the response at the samples [N or m], and the thinnest film over the run
        (units of d_c; must stay > 0; -inf when the run did not reach its last sample).
    """
    channel, film = _stepper_output(solver_inputs(theta, data, spec), data, solver, spec)
    return _response(theta, channel, data, spec), film


def _scaled(y, data: TraceData):
    """r_k = w_k (y_k - y_k^data)/σ."""
    return data.weight * (y - data.response) / data.noise


def residuals(theta, data: TraceData, solver: Solver, spec: ModelSpec):
    """The residuals r_k = w_k (y_k(θ) - y_k^data)/σ (misfit in units of the trace's noise).

    Args:
        theta: θ, as :func:`predict`.
        data: the trace's :class:`TraceData`.
        solver: the :class:`Solver`.
        spec: the :class:`ModelSpec`.

    Returns:
        (r, h̄_min): the residuals (dimensionless, one per padded sample) and the thinnest
        film, as :func:`predict`.
    """
    y, film_min = predict(theta, data, solver, spec)
    return _scaled(y, data), film_min


def residuals_and_jacobian(theta, data: TraceData, solver: Solver, spec: ModelSpec):
    """The residuals and their Jacobian, by forward mode.

    By the chain rule through u = u(θ) (``solver_inputs``): one jvp of the stepper per
    component of u (vmap-ed; 2 for a prescribed travel on an elastic solid, where θ has 4),
    ∂c/∂θ = ∂c/∂u · ∂u/∂θ for the stepper's channel c, then the cheap response map's jvp in θ
    and c together.

    Args:
        theta: θ, as :func:`predict`.
        data: the trace's :class:`TraceData`.
        solver: the :class:`Solver`.
        spec: the :class:`ModelSpec`.

    Returns:
        (r, J, h̄_min): the residuals, J = ∂r/∂θ (shape (samples, len(θ))) and the thinnest
        film, as :func:`residuals`.
    """
    u = solver_inputs(theta, data, spec)
    du = jax.jacfwd(solver_inputs)(theta, data, spec)  # (m, p), exact and cheap

    def column(v):
        (c, film), (dc, _) = jax.jvp(
            lambda x: _stepper_output(x, data, solver, spec), (u,), (v,)
        )
        return c, film, dc

    c, film, dc_du = jax.vmap(column, out_axes=(None, None, 1))(jnp.eye(u.shape[0]))
    dc_dtheta = dc_du @ du

    def res(th, ch):
        return _scaled(_response(th, ch, data, spec), data)

    r = res(theta, c)
    J = jax.vmap(lambda v, dc: jax.jvp(res, (theta, c), (v, dc))[1], in_axes=(0, 1),
                 out_axes=1)(jnp.eye(theta.shape[0]), dc_dtheta)
    return r, J, film


#: The batched functions' arguments (θ, data, solver, active): which carry the trace axis.
_BATCHED = (True, True, False, True)


def _batched(fn, mode: str):
    """``fn(θ, data, solver)`` over a leading trace axis of θ, data and ``active`` (bool per
    trace). ``"map"``: one trace at a time, inactive traces skipped (their outputs zero);
    ``"vmap"``: all at once, ``active`` ignored (a select could not skip the work)."""
    if mode == "vmap":
        def member(theta, data, solver, active):
            return fn(theta, data, solver)
    else:
        fn = jax.jit(fn)  # traced once: eval_shape and the branch share the trace

        def member(theta, data, solver, active):
            shapes = jax.eval_shape(fn, theta, data, solver)
            return jax.lax.cond(
                active,
                lambda: fn(theta, data, solver),
                lambda: jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes),
            )

    return _sharding.batch(member, _BATCHED, mode)


@functools.lru_cache(maxsize=16)
def batched_functions(spec: ModelSpec, mesh=None, mode: str = "vmap"):
    """jit-compiled, trace-batched (r, J, film) and (y, film) for ``spec``, functions of
    (θ, data, solver, active): θ, the data and ``active`` carry the trace axis, the solver is
    shared (its tolerance an argument). ``mode``: "map" or "vmap"
    (:func:`lubjax._sharding.batching_mode`). With a ``mesh`` (lubjax/_sharding.py) the trace
    axis is split over its devices, the solver replicated, and each device maps or vmaps over
    its own traces."""
    fns = (functools.partial(residuals_and_jacobian, spec=spec),
           functools.partial(predict, spec=spec))
    return tuple(
        _compiler.jit(_sharding.over_batch(_batched(f, mode), mesh, _BATCHED)) for f in fns
    )


def stack(datas: list[TraceData]) -> TraceData:
    """Stack per-trace arrays along a new leading (batch) axis."""
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *datas)


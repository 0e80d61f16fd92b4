r"""The problems of a fit and their batched evaluator.

A fit is a set of *problems*, each a parameter vector x and the traces it explains: trace t of
problem k uses θ_t = θ_t⁰ + M_t x (M_t a 0/1 selection, θ_t⁰ the values held fixed). Separate
fits are one problem per trace; a joint fit (``shared=``) is one problem whose x holds the shared
parameters once and the other parameters once per trace (:func:`make_layout`). Every trace of
every problem is evaluated in one ``vmap``-ed (or mapped) call on one mesh (:func:`fit_mesh`,
:class:`Evaluator`), and the solver's error at the optimum in one more (:func:`solver_error`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

import lubjax
from lubjax._fitting_api import estimate as _estimate
from lubjax._fitting_api import sharding as _sharding
from lubjax._fitting_api import single_threaded_blas

from . import _cache, _model, _scales
from ._model import ModelSpec


class Layout(NamedTuple):
    """Where each trace's θ comes from: θ_t = base[t] + M[t] @ x of its problem."""

    problem: np.ndarray  # (T,) problem index of each trace
    base: np.ndarray  # (T, P)
    M: list  # per trace (P, n_k)
    labels: list  # per problem: parameter labels of x
    active: np.ndarray  # (P,) which θ components are fitted (not held fixed)


def make_layout(groups, spec: ModelSpec, names_of_traces, theta0, shared,
            fixed=()) -> tuple[Layout, list]:
    """Parameter layout and starting x for problems ``groups`` (lists of trace indices); the
    ``fixed`` parameters stay at their θ0 like an offset that is not fitted."""
    P = len(spec.names)
    active = spec.active & np.array([n not in fixed for n in spec.names])
    T = theta0.shape[0]
    problem = np.zeros(T, int)
    base = np.where(active, 0.0, theta0)
    M = [None] * T
    labels, x0s = [], []
    for k, members in enumerate(groups):
        sh = [i for i, n in enumerate(spec.names) if active[i] and n in shared and len(members) > 1]
        own = [i for i in range(P) if active[i] and i not in sh]
        n = len(sh) + len(own) * len(members)
        lab = [spec.names[i] for i in sh]
        x0 = [float(np.mean(theta0[members, i])) for i in sh]
        for j, t in enumerate(members):
            problem[t] = k
            m = np.zeros((P, n))
            for a, i in enumerate(sh):
                m[i, a] = 1.0
            for a, i in enumerate(own):
                m[i, len(sh) + j * len(own) + a] = 1.0
            M[t] = m
            suffix = f"[{names_of_traces[t]}]" if len(members) > 1 else ""
            lab += [spec.names[i] + suffix for i in own]
            x0 += [float(theta0[t, i]) for i in own]
        labels.append(lab)
        x0s.append(np.array(x0))
    return Layout(problem, base, M, labels, active), x0s


class Evaluator:
    """(r, J, film) of every problem at given x, in one call over all traces (mapped or vmap-ed:
    ``lubjax._sharding.batching_mode``).

    The trace axis is split over ``devices`` devices (lubjax/_sharding.py): the stacked data
    and θ are padded to a multiple of the device count (repeating the last trace) and laid out
    with ``NamedSharding(mesh, P("batch"))``, the solver (mesh arrays) replicated, and the one
    jit-ed call is a ``shard_map`` of the vmap-ed model over the devices; the padded rows are
    cut off. With one device nothing is padded or placed."""

    def __init__(self, data, solver, spec, layout: Layout, groups, devices: int = 1,
                 batching: str = "auto"):
        self.data, self.solver, self.spec = data, solver, spec
        self.layout, self.groups = layout, groups
        self.mesh = _sharding.batch_mesh(devices)
        self.mode = _sharding.batching_mode(batching)
        self.rj = self.batched(0, "residuals_and_jacobian")
        self.runs = 0
        self.n_traces = len(layout.M)
        self.pad = _sharding.padding(self.n_traces, devices)
        self._placed = self.place(data, solver)  # the data do not change between iterations

    def place(self, data, solver):
        """(data, solver) padded and put on the mesh (unchanged with one device)."""
        return (_sharding.shard_batch(_sharding.pad_leading(data, self.pad), self.mesh),
                _sharding.replicate(solver, self.mesh))

    def batched(self, which: int, name: str):
        """The batched model function ``which`` (0: (r, J, film), 1: (y, film)), through the
        stored-program cache."""
        return _cache.exported(f"{name} {self.mode} {self.spec!r}",
                               _model.batched_functions(self.spec, self.mesh, self.mode)[which])

    def run(self, theta, placed=None, fn=None, active=None):
        """``fn`` (default the model's (r, J, film)) of all traces at θ (n_traces × p) as NumPy
        arrays, on ``placed`` data and solver (default: the fit's own). ``active`` (bool per
        trace, default all): with batching "map" the others are skipped and come back as
        zeros; "vmap" computes them all."""
        data, solver = self._placed if placed is None else placed
        fn = self.rj if fn is None else fn
        active = np.ones(self.n_traces, bool) if active is None else np.asarray(active, bool)
        # Padding rows repeat the last trace; they are skipped under "map".
        active = np.concatenate([active, np.zeros(self.pad, bool)])
        theta = _sharding.pad_leading(np.asarray(theta), self.pad)
        theta, active = (_sharding.shard_batch(jnp.asarray(a), self.mesh) for a in (theta, active))
        with single_threaded_blas():
            out = fn(theta, data, solver, active)
            return tuple(_sharding.to_host(a)[: self.n_traces] for a in out)

    def residuals(self, xs, k):
        """Problem k's residuals at x from the response alone (no Jacobian: about a quarter of
        a run with it), or None where the run fails (a negative film or a non-finite value)."""
        active = np.zeros(self.n_traces, bool)
        active[self.groups[k]] = True
        y, film = self.run(self.thetas(xs), fn=self.batched(1, "predict"), active=active)
        self.runs += 1
        members = self.groups[k]
        r_all = scaled_residuals(self.data, y)
        r = np.concatenate([r_all[t] for t in members])
        ok = bool(np.isfinite(r).all() and all(film[t] > 0 for t in members))
        return r if ok else None

    def thetas(self, xs):
        lay = self.layout
        return np.stack([lay.base[t] + lay.M[t] @ xs[lay.problem[t]] for t in range(len(lay.M))])

    def __call__(self, xs, problems=None):
        """(r, J, ok) per problem at x; only ``problems`` (indices; default all) are computed
        where the batching can skip (the others' entries are then None)."""
        wanted = np.zeros(len(self.groups), bool)
        wanted[slice(None) if problems is None else list(problems)] = True
        active = np.zeros(self.n_traces, bool)
        for k in np.flatnonzero(wanted):
            active[self.groups[k]] = True
        r, J, film = self.run(self.thetas(xs), active=active)
        self.runs += 1
        out = []
        for k, members in enumerate(self.groups):
            if not wanted[k] and self.mode == "map":
                out.append(None)
                continue
            rk = np.concatenate([r[t] for t in members])
            Jk = np.concatenate([J[t] @ self.layout.M[t] for t in members])
            ok = bool(np.isfinite(rk).all() and np.isfinite(Jk).all() and all(
                film[t] > 0 for t in members))
            out.append((rk, Jk, ok))
        return out


def scaled_residuals(data, y) -> np.ndarray:
    """r = w (y - y_data)/σ of every trace of the stacked ``data`` at responses ``y``."""
    return np.array(data.weight * (y - data.response) / data.noise[:, None])


def fit_mesh(traces, starts, scales, spec, settings) -> lubjax.Mesh:
    """The mesh a fit runs on: the one :func:`lubjax.mesh_for` gives a relax run of each trace
    at its starting values (β, z̄0), refined at the contact's edge where the run ends in a
    contact whose neck needs it (near-dry traces, β ≳ 10⁵), where every trace of the batch
    asks for the same mesh; else ``settings.mesh()`` (the batch shares one mesh). Not padded
    (``mesh_for(padded=False)``): a fit compiles one program for all its runs.

    Args:
        traces: the :class:`Trace` s fitted together.
        starts: their :class:`Start` values.
        scales: their :class:`Scales`.
        spec: the :class:`ModelSpec`.
        settings: the fit's ``lubjax.Settings``.

    Returns:
        lubjax.Mesh: the shared mesh.
    """
    meshes = []
    for trace, start, sc in zip(traces, starts, scales, strict=True):
        E_star = start.values["E_star"]
        beta = lubjax.si_scales(E_star, sc.radius, sc.indent, t_c=sc.time_scale,
                                viscosity=start.values["viscosity"])["beta"]
        hist = _scales.history(trace, sc, spec.drive)
        drive = _model.make_drive(spec.drive, _scales.drive_unit(trace, sc, spec.drive), hist,
                                  E_star)
        try:
            meshes.append(lubjax.mesh_for(settings, drive=drive, beta=beta,
                                          z0=start.values["z0"] / sc.indent,
                                          t_end=float(hist.t[-1]), padded=False))
        except ValueError:  # a start outside the solver's (β, z̄0) range: the shared mesh
            return settings.mesh()
    return meshes[0] if all(m == meshes[0] for m in meshes) else settings.mesh()


def stack_traces(traces, scales, spec, mesh):
    n_pad = max(tr.time.size for tr in traces)
    n_hist = max(_scales.history_size(tr, s) for tr, s in zip(traces, scales, strict=True))
    return _model.stack([_model.trace_data(tr, s, spec, mesh, n_pad, n_hist)
                         for tr, s in zip(traces, scales, strict=True)])


def solver_error(evaluate, xs, r_fit, traces, scales, spec, settings, mesh, groups):
    """Signed error of the model response at the optimum, per problem in residual units.

    One extra run on the nested coarse mesh (every other node) at ``Tolerance.loosened()``
    (8·rtol), with Richardson's estimate (``lubjax._estimate.richardson``) at the scheme's
    asymptotic orders: space 2 (×4 at twice the spacing) and time 2/3 in rtol (×4 at 8·rtol).
    Both errors grow by the same factor, so y_coarse,8rtol - y ≈ 3 (error of y) and one run
    gives the error, (y_coarse,8rtol - y)/3. ``lubjax.relax``'s estimate
    (``lubjax._estimate.error_estimate``) separates space and time with two runs at the lower
    orders 3/2 and 1/2, times a safety factor of 3: a pointwise bound. Here the signed error
    enters the budget as a parameter shift (:func:`fitting._stats.summarise`), where a bound
    would be too large. In residual units (r = w (y - y_data)/σ) it is (r_coarse,8rtol - r)/3;
    the run is the fit's own model (the response only: no Jacobian) on the other solver."""
    mesh = mesh.coarsened()
    tol = settings.tolerance()
    loose = _model.Solver(lubjax.stepper.discretise(mesh), tol.loosened())
    data = stack_traces(traces, scales, spec, mesh)
    # The response alone (no Jacobian): a forward run, a quarter of the cost and of the tracing.
    predict = evaluate.batched(1, "predict")
    y_loose = evaluate.run(evaluate.thetas(xs), evaluate.place(data, loose), predict)[0]
    r_loose = scaled_residuals(data, y_loose)
    # 8^{2/3} = 2^2: the one run's space and time errors grow alike, by 2^2
    err = _estimate.richardson(r_loose - r_fit, 2.0, _estimate.SMOOTH_SPACE_ORDER)
    err[~np.isfinite(err)] = 0.0
    return [np.concatenate([err[t] for t in g]) for g in groups]


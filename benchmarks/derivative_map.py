"""Derivative map: forward and reverse derivatives of a run against central differences of
converged runs, over the stability map, every drive and substrate; and what they cost.

    python -m benchmarks.derivative_map [--quick]     # the map
    python -m benchmarks.derivative_map --cost        # grad and jacfwd against the primal
    python -m benchmarks.derivative_map --min-beta 1e7  # the near-dry cells alone
    python -m benchmarks.derivative_map --min-beta 1e7 --group viscoelastic --dr 0.007
                                                      # one scene, on a finer mesh
    python -m benchmarks.derivative_map --min-beta 1e9 --rtol 3e-5
                                                      # AD at a tighter tolerance

Each cell is a run on the mesh :func:`lubjax.relax` gives it when differentiated
(``lubjax.mesh_for(..., derivatives=True)``, default settings) with its response read at
``TIMES_PER_CELL`` times in [t_end/12, t_end]: F̄ for a prescribed travel and a spring, the
gap z̄ under a load and for a free sphere. On that mesh:

* AD: ``jax.jacfwd`` and ``jax.jacrev`` of the response with respect to (ln β, z̄0), at the
  default tolerance (rtol 1e-4);
* the reference: central differences of runs at rtol ``REF_RTOL`` on the same mesh, with steps
  h and 2h (h = 2e-3 in ln β and 2e-3 max(z̄0, 0.1) in z̄0); their disagreement says how well
  the reference itself is known.

Per parameter: error = max over the times of |AD - CD_h| over max |CD_h|; reference = the same
of |CD_h - CD_2h|; per cell, the run's error = max |y - y_ref| over max |y_ref| of the
response at the default tolerance against the run at ``REF_RTOL`` (a derivative is that of
values known only this well); reverse = |jacrev - jacfwd| over max |jacfwd| (the adjoint
against the forward replay). Each (cell, parameter) is classified, first match: failed (NaN,
or a run that did not finish), ok (error ≤ 1e-3), reference noise (the reference is known only
to > 1e-3 and the error is within 3× of that: the reference cannot tell), below resolution
(the response moves by less than 10 rtol of its range for a unit change of the parameter, and
AD is within 1e-3 of that range: a derivative under the solver's own error), inaccurate.

Cells (``--quick``: the first four β of each group and z̄0 ∈ {0.5}):
  travel on the half-space, β ∈ {0.1, 10, 10³, 10⁵, 10⁷, 10⁹} × z̄0 ∈ {0.05, 0.1, 0.5, 2, 5},
  t̄ ≤ 10;
  travel on a bonded layer (thickness 2 √(R d_c)) and on a viscoelastic solid (E₀/E∞ = 3,
  τ = 0.5), load, spring (K̄ = 2) and free sphere (1/m̄ = 50 β/100, weight 0.1, from z̄0 = 1),
  β ∈ {10, 10⁴, 10⁷}, z̄0 = 0.5, t̄ ≤ 5;
  long holds, travel, β ∈ {10², 10⁴}, z̄0 = 0.5, t̄ ≤ 10³.

``--cost``: warm times of the primal, ``jax.grad`` of a scalar and ``jax.jacfwd`` in (β, z̄0)
of relax's run (β = 100, z̄0 = 0.5, t̄ ≤ 5, default settings, no error estimate) at
``max_steps`` 500, 2000, 20 000 and 80 000, and the ratios to the primal (each the best of 3);
and near dry (β = 10⁹, z̄0 = 0.1), where a differentiated relax runs on a finer mesh with the
film held tighter, the same three of relax itself (:func:`near_dry_cost`).

``--dr``: the cells' meshes with this fine-zone spacing Δr̄ (``Settings.dr``; default the
tolerance's, 0.014), to tell what the mesh does to a derivative from what the steps do;
``--rtol``: the AD runs' step tolerance on the default's mesh, to tell what the steps do.

Writes benchmarks/out/derivative_map{,_quick}.{csv,md} (after every cell; with ``--group``,
``--min-beta``, ``--z0``, ``--dr`` or ``--rtol`` in the name) or
benchmarks/out/derivative_cost.md.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import lubjax
from benchmarks import _harness
from lubjax.stepper import discretise, evaluate, rollout

REF_RTOL = 1e-6
TIMES_PER_CELL = 12
STEP = 2e-3
CATEGORIES = ("ok", "reference noise", "below resolution", "inaccurate", "failed")
PARAMETERS = ("ln β", "z̄0")
GROUPS = ("travel", "layer", "viscoelastic", "load", "spring", "free sphere", "long hold")


def _scenes(quick: bool):
    """(group, drive, substrate, β, z̄0, t_end, channel) of every cell."""
    halfspace = lubjax.HalfSpace()
    cells = []
    betas = (0.1, 10.0, 1e3, 1e5, 1e7, 1e9)
    z0s = (0.05, 0.1, 0.5, 2.0, 5.0)
    for beta in betas[:4] if quick else betas:
        for z0 in (0.5,) if quick else z0s:
            cells.append((GROUPS[0], lubjax.Travel(), halfspace, beta, z0, 10.0, "force"))
    # the scenes of GROUPS[1:-1], in that order
    others = [
        (lambda b: lubjax.Travel(), lubjax.Layer(2.0), 0.5, "force"),
        (lambda b: lubjax.Travel(), lubjax.Viscoelastic.standard_linear_solid(3.0, 0.5), 0.5,
         "force"),
        (lambda b: lubjax.Load(), halfspace, 0.5, "gap"),
        (lambda b: lubjax.Spring(2.0), halfspace, 0.5, "force"),
        (lambda b: lubjax.FreeSphere(inverse_mass=0.5 * b, weight=0.1), halfspace, 1.0, "gap"),
    ]
    for group, (drive, substrate, z0, channel) in zip(GROUPS[1:-1], others, strict=True):
        for beta in (10.0,) if quick else (10.0, 1e4, 1e7):
            cells.append((group, drive(beta), substrate, beta, z0, 5.0, channel))
    if not quick:
        for beta in (1e2, 1e4):
            cells.append((GROUPS[-1], lubjax.Travel(), halfspace, beta, 0.5, 1e3, "force"))
    return cells


def _response(disc, drive, substrate, t_end, tol, times, channel):
    def f(p):
        traj = rollout(disc, jnp.exp(p[0]), p[1], drive, t_end, tol, substrate=substrate)
        return evaluate(traj.steps, times, channel), traj.finished

    return f


def check_cell(drive, substrate, beta, z0, t_end, channel, ref_rtol=REF_RTOL, dr=None,
               rtol=None):
    """AD (jacfwd, jacrev) of the response of a run at ``rtol`` (default the default
    tolerance's) against central differences of runs at ``ref_rtol`` on the same mesh (``dr``:
    its fine zone's spacing, default the default tolerance's); returns a dict of the errors per
    parameter and the cell's facts."""
    settings = lubjax.Settings(error_estimate=False, dr=dr)
    mesh = lubjax.mesh_for(settings, drive=drive, beta=beta, z0=z0, t_end=t_end,
                           derivatives=True)
    disc = discretise(mesh, substrate)
    if rtol is not None:  # the steps' tolerance only: the mesh stays the default's
        settings = dataclasses.replace(settings, rtol=rtol)
    times = jnp.linspace(t_end / TIMES_PER_CELL, t_end, TIMES_PER_CELL)
    f = _response(disc, drive, substrate, t_end, settings.tolerance(), times, channel)
    p = jnp.array([np.log(beta), z0])
    start = time.perf_counter()
    y, finished = jax.jit(f)(p)
    values = jax.jit(lambda p: f(p)[0])
    jac_fwd = np.asarray(jax.jit(jax.jacfwd(values))(p))
    jac_rev = np.asarray(jax.jit(jax.jacrev(values))(p))
    ad_s = time.perf_counter() - start
    reference = lubjax.Settings(rtol=ref_rtol, max_steps=200_000, dr=dr).tolerance()
    g = _response(disc, drive, substrate, t_end, reference, times, channel)
    steps = np.array([STEP, STEP * max(z0, 0.1)])
    points = [p] + [p + s * k * steps[j] * jnp.eye(2)[j] for k in (1, 2) for j in range(2)
                    for s in (1, -1)]
    start = time.perf_counter()
    refs, done = jax.jit(lambda ps: jax.lax.map(g, ps))(jnp.stack(points))
    ref_s = time.perf_counter() - start
    converged, refs = np.asarray(refs[0]), np.asarray(refs[1:]).reshape(2, 2, 2, -1)
    central = (refs[:, :, 0] - refs[:, :, 1]) / (2 * np.array([1, 2])[:, None, None]
                                                   * steps[None, :, None])
    y = np.asarray(y)
    span = float(np.max(np.abs(y)))
    # the run's own error: how well the values are known whose derivative this is
    value_error = float(np.max(np.abs(y - converged)) / np.max(np.abs(converged)))
    out = dict(N=mesh.size, ad_s=ad_s, ref_s=ref_s, value_error=value_error,
               finished=bool(finished) and bool(np.all(np.asarray(done))))
    for j, name in enumerate(PARAMETERS):
        cd, cd2 = central[0, j], central[1, j]
        scale = float(np.max(np.abs(cd)))
        error = float(np.max(np.abs(jac_fwd[:, j] - cd))) / scale if scale > 0 else np.inf
        ref = float(np.max(np.abs(cd - cd2))) / scale if scale > 0 else np.inf
        reverse = float(np.max(np.abs(jac_rev[:, j] - jac_fwd[:, j]))
                        / max(np.max(np.abs(jac_fwd[:, j])), 1e-300))
        finite = np.all(np.isfinite(jac_fwd[:, j])) and np.all(np.isfinite(jac_rev[:, j]))
        if not (finite and out["finished"] and np.all(np.isfinite(cd))):
            category = "failed"
        elif error <= 1e-3:
            category = "ok"
        elif ref > 1e-3 and error <= 3 * ref:
            category = "reference noise"
        elif (scale < 10 * settings.rtol * span
              and np.max(np.abs(jac_fwd[:, j] - cd)) <= 1e-3 * span):
            category = "below resolution"
        else:
            category = "inaccurate"
        out[name] = dict(error=error, reference=ref, reverse=reverse, scale=scale,
                         category=category)
    return out


FIELDS = ("group", "beta", "z0", "t_end", "N", "parameter", "category", "error", "reference",
          "value_error", "reverse", "scale", "ad_s", "ref_s")


def _write(rows, path, command, machine):
    with open(path + ".csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    lines = [
        "# Derivative map", "",
        f"`{command}` ({machine}). AD at the default tolerance on relax's mesh against "
        f"central differences of runs at rtol {REF_RTOL:g} on the same mesh; error and "
        "reference relative to the largest |derivative|; the run's error: its values against "
        "the converged run's, relative to their largest.", "",
        "| scene | β | z̄0 | t̄_end | N | parameter | class | error | reference | "
        "the run's error | jacrev vs jacfwd |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['group']} | {r['beta']:g} | {r['z0']:g} | {r['t_end']:g} | {r['N']} | "
            f"{r['parameter']} | {r['category']} | {r['error']:.1e} | {r['reference']:.1e} | "
            f"{r['value_error']:.1e} | {r['reverse']:.1e} |")
    counts = {c: sum(r["category"] == c for r in rows) for c in CATEGORIES}
    lines += ["", "Classes: " + ", ".join(f"{c} {n}" for c, n in counts.items() if n)]
    _harness.write_report(path + ".md", lines)


def derivative_map(args, argv):
    path = os.path.splitext(args.out)[0] + ("_quick" if args.quick else "")
    if args.min_beta is not None:
        path += f"_beta_from_{args.min_beta:g}"
    if args.group is not None:
        path += "_" + args.group.replace(" ", "_")
    if args.z0 is not None:
        path += f"_z0_{args.z0:g}"
    if args.dr is not None:
        path += f"_dr_{args.dr:g}"
    if args.rtol is not None:
        path += f"_rtol_{args.rtol:g}"
    rows = []
    cells = [c for c in _scenes(args.quick) if (args.min_beta is None or c[3] >= args.min_beta)
             and (args.group is None or c[0] == args.group)
             and (args.z0 is None or c[4] == args.z0)]
    for k, (group, drive, substrate, beta, z0, t_end, channel) in enumerate(cells, 1):
        print(f"[{k}/{len(cells)}] {group}, β = {beta:g}, z̄0 = {z0:g}, t̄ ≤ {t_end:g}",
              flush=True)
        try:
            cell = check_cell(drive, substrate, beta, z0, t_end, channel, dr=args.dr,
                              rtol=args.rtol)
        except (lubjax.SolverError, ValueError) as exc:
            print(f"  refused: {exc}", flush=True)
            continue
        for name in PARAMETERS:
            r = cell[name]
            rows.append(dict(group=group, beta=beta, z0=z0, t_end=t_end, N=cell["N"],
                             parameter=name, category=r["category"], error=r["error"],
                             reference=r["reference"], value_error=cell["value_error"],
                             reverse=r["reverse"], scale=r["scale"],
                             ad_s=round(cell["ad_s"], 1), ref_s=round(cell["ref_s"], 1)))
            print(f"  {name}: {r['category']} (error {r['error']:.1e}, reference "
                  f"{r['reference']:.1e}, the run's {cell['value_error']:.1e}, jacrev vs "
                  f"jacfwd {r['reverse']:.1e})", flush=True)
        _write(rows, path, _harness.command(argv), _harness.label())


def _best(fn, *args, repeat=3):
    return _harness.timed(fn, *args, repeat=repeat)[2]


class RunCost(NamedTuple):
    """Warm seconds (best of 3) of relax's run of the cost scene and of its derivatives."""

    nodes: int
    accepted: int
    primal: float
    grad: float  # jax.grad of the sum of F̄ at 50 times
    jacfwd: float  # jax.jacfwd of it in (β, z̄0)


def run_cost(max_steps: int | None = None, beta=100.0, z0=0.5, t_end=5.0) -> RunCost:
    """relax's run (default settings, no error estimate; ``max_steps`` default the settings')
    on its own mesh: the primal, ``jax.grad`` of the sum of F̄ at 50 times and ``jax.jacfwd`` of
    it in (β, z̄0), each warm, best of 3."""
    settings = lubjax.Settings(error_estimate=False)
    if max_steps is not None:
        settings = dataclasses.replace(settings, max_steps=max_steps)
    mesh = lubjax.mesh_for(settings, drive=lubjax.Travel(), beta=beta, z0=z0, t_end=t_end)
    disc, tol = discretise(mesh), settings.tolerance()
    times = jnp.linspace(0.1, t_end, 50)

    def total(p):
        traj = rollout(disc, p[0], p[1], lubjax.Travel(), t_end, tol)
        return jnp.sum(evaluate(traj.steps, times, "force"))

    p = jnp.array([beta, z0])
    accepted = int(jax.jit(lambda p: rollout(disc, p[0], p[1], lubjax.Travel(), t_end,
                                             tol).accepted)(p))
    return RunCost(disc.r.shape[0], accepted, _best(jax.jit(total), p),
                   _best(jax.jit(jax.grad(total)), p), _best(jax.jit(jax.jacfwd(total)), p))


def cost(args, argv):
    beta, z0, t_end = 100.0, 0.5, 5.0
    lines = [
        "# What derivatives cost", "",
        f"`{_harness.command(argv)}` ({_harness.label()}). relax's run (β = {beta:g}, "
        f"z̄0 = {z0:g}, t̄ ≤ {t_end:g}, default settings, no error estimate), warm, best of 3: "
        "the primal, `jax.grad` of the sum of F̄ at 50 times, `jax.jacfwd` of it in (β, z̄0).",
        "", "| max_steps | accepted | primal [s] | grad [s] | jacfwd [s] | grad / primal | "
        "jacfwd / primal |", "|---|---|---|---|---|---|---|",
    ]
    for max_steps in (500, 2000, 20_000, 80_000):
        run = run_cost(max_steps, beta, z0, t_end)
        lines.append(f"| {max_steps} | {run.accepted} | {run.primal:.3f} | {run.grad:.3f} | "
                     f"{run.jacfwd:.3f} | {run.grad / run.primal:.1f} | "
                     f"{run.jacfwd / run.primal:.1f} |")
        print(lines[-1], flush=True)
    # What a step is made of: one dense LU of the run's system per attempt; a derivative adds
    # the replayed step's and the fully implicit Jacobian's.
    size = run.nodes
    matrix = jnp.eye(size) * size + jax.random.normal(jax.random.PRNGKey(0), (size, size))
    lu = _best(jax.jit(lambda a: jax.lax.linalg.lu(a)[0]), matrix, repeat=20)
    lines += ["", f"One LU factorisation of the run's {size}×{size} system: {1e3 * lu:.3f} ms; "
              f"the primal's time per accepted step: {1e3 * run.primal / run.accepted:.3f} ms."]
    print(lines[-1], flush=True)
    lines += near_dry_cost()
    _harness.write_report(os.path.join(os.path.dirname(args.out), "derivative_cost.md"), lines)


def near_dry_cost(beta=1e9, z0=0.1, t_end=5.0):
    """Near dry a differentiated relax runs on a finer mesh with the film held tighter
    (``mesh_for(derivatives=True)``, ``Tolerance.for_tangents``): warm times of the plain run
    and of ``jax.grad`` and ``jax.jacfwd`` of relax itself, and each run's steps."""
    settings = lubjax.Settings(error_estimate=False)
    times = np.linspace(0.1, t_end, 50)

    def total(p):
        return jnp.sum(lubjax.relax(p[0], p[1], t_end, settings=settings).at(times))

    p = jnp.array([beta, z0])
    plain = lubjax.relax(beta, z0, t_end, settings=settings)

    def with_counts(p):  # the differentiated run's mesh and steps (concrete under jvp)
        result = lubjax.relax(p[0], p[1], t_end, settings=settings)
        return jnp.sum(result.at(times)), (result.r.size, int(result.accepted))

    *_, (derived_nodes, derived_steps) = jax.jvp(with_counts, (p,), (jnp.array([0.0, 1.0]),),
                                                 has_aux=True)
    primal = _best(lambda q: lubjax.relax(float(q[0]), float(q[1]), t_end,
                                          settings=settings).force, p)
    grad = _best(jax.grad(total), p)
    forward = _best(jax.jacfwd(total), p)
    lines = [
        "", f"Near dry, β = {beta:g}, z̄0 = {z0:g}, t̄ ≤ {t_end:g} (relax itself, default "
        "settings, no error estimate, warm, best of 3): the plain run on "
        f"{plain.r.size} nodes, {plain.accepted} accepted steps; the differentiated one on "
        f"{derived_nodes} nodes, {derived_steps} steps.", "",
        "| primal [s] | grad [s] | jacfwd [s] | grad / primal | jacfwd / primal |",
        "|---|---|---|---|---|",
        f"| {primal:.3f} | {grad:.3f} | {forward:.3f} | {grad / primal:.1f} | "
        f"{forward / primal:.1f} |",
    ]
    print("\n".join(lines), flush=True)
    return lines


def main(argv=None):
    ap = _harness.parser(__doc__, "derivative_map", quick="4 β, z̄0 = 0.5, one β per scene")
    ap.add_argument("--cost", action="store_true", help="grad and jacfwd against the primal")
    ap.add_argument("--min-beta", type=float, default=None,
                    help="only the cells with beta at least this (writes ..._beta_from_B)")
    ap.add_argument("--group", default=None, choices=GROUPS, help="only this scene's cells")
    ap.add_argument("--z0", type=float, default=None, help="only the cells at this z̄0")
    ap.add_argument("--dr", type=float, default=None,
                    help="the meshes' fine-zone spacing (default: the tolerance's, 0.014)")
    ap.add_argument("--rtol", type=float, default=None,
                    help="the AD runs' step tolerance, on the default tolerance's mesh "
                         "(default: the default, 1e-4)")
    args = _harness.parse(ap, argv)
    if args.cost:
        cost(args, argv)
    else:
        derivative_map(args, argv)


if __name__ == "__main__":
    main()

"""A user's own ``jax.vmap`` against :func:`lubjax.sweep`: the same batch of runs, and the
batch's gradients against the same gradients one at a time.

    python -m benchmarks.vmap_vs_sweep [--batch 8]

The batch: β geometrically spaced in [1, 10⁴], z̄0 = 0.5, t̄ ≤ 5, default settings without the
error estimate, F̄ at 501 times on ``make_plan``'s mesh. Warm times, best of 3 (compile apart):
``sweep``; ``jax.jit(jax.vmap(force_curve))``; ``jax.jit(jax.vmap(relax(...).at))``; the
runs one at a time (a jitted ``force_curve`` in a Python loop); ``jax.jit(jax.vmap(jax.grad))``
of F̄(5) against the jitted ``grad`` in a loop. And whether each batch member is its run alone
to the last bit. Writes benchmarks/out/vmap_vs_sweep.md.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import lubjax
from benchmarks import _harness


def main(argv=None):
    ap = _harness.parser(__doc__, "vmap_vs_sweep.md")
    ap.add_argument("--batch", type=int, default=8, help="runs in the batch")
    args = _harness.parse(ap, argv)
    settings = lubjax.Settings(error_estimate=False)
    t_end, z0 = 5.0, 0.5
    plan = lubjax.make_plan(t_end, settings=settings)
    betas = jnp.geomspace(1.0, 1e4, args.batch)

    def curve(b):
        return lubjax.force_curve(plan, b, z0)

    def relaxed(b):
        return lubjax.relax(b, z0, t_end, settings=settings).at(plan.t)

    def peak(b):
        return lubjax.force_curve(plan, b, z0)[-1]

    rows = []
    swept = lubjax.sweep(np.asarray(betas), np.full(args.batch, z0), t_end, settings=settings,
                         times=plan.t)
    _, _, sweep_s = _harness.timed(lambda: lubjax.sweep(np.asarray(betas), np.full(args.batch, z0),
                                                t_end, settings=settings, times=plan.t).force)
    rows.append(("`sweep`", swept.compile_s, sweep_s, "—"))
    one = jax.jit(curve)
    alone = np.stack([np.asarray(one(b)) for b in betas])
    _, _, loop_s = _harness.timed(lambda: [one(b) for b in betas])
    for name, fn in (("`jit(vmap(force_curve))`", curve), ("`jit(vmap(relax(...).at))`", relaxed)):
        out, first, warm = _harness.timed(jax.jit(jax.vmap(fn)), betas)
        same = "yes" if np.array_equal(np.asarray(out), alone) else (
            f"no, {np.nanmax(np.abs(np.asarray(out) - alone)):.1e} of F̄")
        rows.append((name, first - warm, warm, same))
    rows.append(("jitted `force_curve`, one at a time", float("nan"), loop_s, "—"))
    grad_one = jax.jit(jax.grad(peak))
    grads_alone = np.array([float(grad_one(b)) for b in betas])
    _, _, grad_loop_s = _harness.timed(lambda: [grad_one(b) for b in betas])
    out, first, warm = _harness.timed(jax.jit(jax.vmap(jax.grad(peak))), betas)
    same = "yes" if np.array_equal(np.asarray(out), grads_alone) else (
        f"no, {np.max(np.abs(np.asarray(out) / grads_alone - 1)):.1e} relative")
    rows.append(("`jit(vmap(grad(F̄(5))))`", first - warm, warm, same))
    rows.append(("jitted `grad(F̄(5))`, one at a time", float("nan"), grad_loop_s, "—"))

    lines = [
        "# A user's vmap against sweep", "",
        f"`{_harness.command(argv)}` ({_harness.label()}). {args.batch} runs, β in [1, 10⁴], "
        f"z̄0 = {z0:g}, t̄ ≤ {t_end:g}, default settings without the error estimate, F̄ at "
        f"{plan.t.size} times on make_plan's {len(plan.mesh.r)}-node mesh; warm, best of 3.",
        "", "| call | compile [s] | warm [s] | each member its run alone |", "|---|---|---|---|",
    ]
    for name, compile_s, warm, same in rows:
        compile_text = "—" if np.isnan(compile_s) else f"{compile_s:.2f}"
        lines.append(f"| {name} | {compile_text} | {warm:.2f} | {same} |")
    for line in lines[-len(rows):]:
        print(line, flush=True)
    _harness.write_report(args.out, lines)


if __name__ == "__main__":
    main()

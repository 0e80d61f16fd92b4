"""What a derivative costs per step, part by part: where ``jax.grad`` of a run spends the ~4
primal runs it takes (docs/accuracy.md, "Cost of a derivative").

    python -m benchmarks.studies.derivative_step_cost

On relax's mesh for the default scene (β = 100, z̄0 = 0.5, t̄ ≤ 5, default settings, no error
estimate), warm, in milliseconds per step:

* one dense LU factorisation of the run's system, and one with a solve on its factors;
* one replayed accepted step (lubjax/_adjoint.py): its values alone, with one tangent (``jvp``),
  with two (``jacfwd`` in β and z̄0, what a fit's Jacobian does with its parameters) and its
  ``grad``; each step's derivative is the fully implicit step's (lubjax/_stepper.py), whose
  Jacobian is assembled and factorised on top of the step's own factorisation;
* a ``lax.scan`` of SCAN_STEPS replayed steps, values and ``grad``;
* the whole run: the primal's time per accepted step, and ``jax.grad``'s and ``jax.jacfwd``'s
  time beyond the primal's per accepted step (the replay and, for grad, the adjoint over the
  checkpointed blocks).

Each per-step figure is a ``fori_loop`` of REPEATS calls (10 for the scans), the best of 5, with
every call made to depend on the last (its times moved by the running sum times 10⁻³⁰⁰) so that
XLA cannot hoist the work out of the loop; the run's rows are
``benchmarks.derivative_map.run_cost`` (best of 3). Writes benchmarks/out/derivative_step_cost.md.
About a minute on one core.
"""

from __future__ import annotations

import time

from benchmarks import _harness

REPEATS = 200
SCAN_STEPS = 45
BETA, Z0, T_END = 100.0, 0.5, 5.0


def _per_call(fn, *args, repeat: int = REPEATS) -> float:
    """Milliseconds per call of ``fn(*args, c)`` (a scalar out), in a loop where each call's
    ``c`` is the running sum of the calls before it."""
    import jax

    loop = jax.jit(lambda *a: jax.lax.fori_loop(0, repeat, lambda i, c: c + fn(*a, c), 0.0))
    jax.block_until_ready(loop(*args))
    best = float("inf")
    for _ in range(5):
        start = time.perf_counter()
        jax.block_until_ready(loop(*args))
        best = min(best, time.perf_counter() - start)
    return 1e3 * best / repeat


def measure() -> tuple[int, list[tuple[str, float]]]:
    """The mesh's node count and (what, ms per step) of every row of the report."""
    import jax
    import jax.numpy as jnp

    import lubjax
    from benchmarks.derivative_map import run_cost
    from lubjax._adjoint import _replay_start, _replay_step
    from lubjax._drives import as_drive
    from lubjax._loop import Inputs
    from lubjax._substrate import as_substrate
    from lubjax.stepper import discretise

    settings = lubjax.Settings(error_estimate=False)
    mesh = lubjax.mesh_for(settings, drive=lubjax.Travel(), beta=BETA, z0=Z0, t_end=T_END)
    disc, size = discretise(mesh), mesh.size
    inputs = Inputs(disc, jnp.asarray(BETA), jnp.asarray(Z0), as_drive(lubjax.Travel()),
                    as_substrate(None), jnp.asarray(T_END), settings.tolerance(),
                    jnp.zeros((0,)))
    dt = 0.01
    # A state on the ramp: 30 steps of dt from rest.
    point, _ = _replay_start(inputs)
    advance = jax.jit(lambda p, t: _replay_step(inputs, p, t, t + dt, 2)[0])
    t = 0.0
    for _ in range(30):
        point, t = advance(point, jnp.asarray(t)), t + dt

    def replayed(beta, z0, p, c, k=0):
        """Step k (of dt) from ``p`` again, with β and z̄0 as given: (new point, F̄)."""
        new, series = _replay_step(inputs._replace(beta=beta, z0=z0), p,
                                   t + k * dt + c * 1e-300, t + (k + 1) * dt, 2)
        return new, series.force

    def force(beta, z0, p, c):
        return replayed(beta, z0, p, c)[1]

    def one_tangent(p, c):
        return jax.jvp(lambda b: force(b, inputs.z0, p, c), (inputs.beta,), (1.0,))[1]

    def two_tangents(p, c):
        return sum(jax.jacfwd(force, argnums=(0, 1))(inputs.beta, inputs.z0, p, c))

    def scan(beta, p, c):
        one = lambda p, k: replayed(beta, inputs.z0, p, c, k)  # noqa: E731
        return jnp.sum(jax.lax.scan(one, p, jnp.arange(SCAN_STEPS))[1])

    matrix = jnp.eye(size) * size + jax.random.normal(jax.random.PRNGKey(0), (size, size))
    rhs = jnp.ones(size)
    run = run_cost()
    return size, [
        ("LU factorisation", _per_call(
            lambda a, c: jax.lax.linalg.lu(a + c * 1e-300)[0][0, 0], matrix)),
        ("LU factorisation and one solve", _per_call(
            lambda a, c: jax.scipy.linalg.lu_solve(
                jax.lax.linalg.lu(a + c * 1e-300)[:2], rhs)[0], matrix)),
        ("replayed step, values", _per_call(lambda p, c: force(inputs.beta, inputs.z0, p, c),
                                            point)),
        ("replayed step, jvp (one tangent)", _per_call(one_tangent, point)),
        ("replayed step, jacfwd (two tangents)", _per_call(two_tangents, point)),
        ("replayed step, grad", _per_call(
            lambda p, c: jax.grad(force)(inputs.beta, inputs.z0, p, c), point)),
        (f"scan of {SCAN_STEPS} replayed steps, values, per step",
         _per_call(lambda p, c: scan(inputs.beta, p, c), point, repeat=10) / SCAN_STEPS),
        (f"scan of {SCAN_STEPS} replayed steps, grad, per step",
         _per_call(lambda p, c: jax.grad(scan)(inputs.beta, p, c), point, repeat=10)
         / SCAN_STEPS),
        (f"the run ({run.accepted} accepted steps): primal, per accepted step",
         1e3 * run.primal / run.accepted),
        ("the run: jacfwd beyond the primal, per accepted step",
         1e3 * (run.jacfwd - run.primal) / run.accepted),
        ("the run: grad beyond the primal, per accepted step",
         1e3 * (run.grad - run.primal) / run.accepted),
    ]


def main(argv=None):
    ap = _harness.parser(__doc__, "derivative_step_cost.md")
    args = _harness.parse(ap, argv)
    size, rows = measure()
    lines = ["# What a derivative costs per step", "",
             f"`{_harness.command(argv)}` ({_harness.label()}); relax's mesh for β = {BETA:g}, "
             f"z̄0 = {Z0:g}, t̄ ≤ {T_END:g} ({size} nodes), default settings, no error "
             "estimate; warm, best of 5 (the run's rows best of 3).", "",
             "| what | ms |", "|---|---|"]
    lines += [f"| {name} | {ms:.3f} |" for name, ms in rows]
    print("\n".join(lines), flush=True)
    _harness.write_report(args.out, lines)


if __name__ == "__main__":
    main()

"""Two revisions side by side on every scene: do they give the same answers?

    python -m benchmarks.same_answers REV_A [REV_B]      # REV_B default: the working tree
    python -m benchmarks.same_answers REV_A --quick      # the short scenes only

Each revision runs every scene of :data:`SCENES` in its own fresh process (REV_A from a temporary
git worktree; the working tree as it is), and the outputs are compared array by array: the
accuracy table's 20 cases (``benchmarks/accuracy.py``: β 1..1000 × z̄0 0.5..2, to t̄ = 10³), every
drive (travel, sampled travel with a smooth start, load, spring, free sphere) and substrate
(half-space, bonded layer, viscoelastic) at orders 1, 2 and 3, the error estimate's runs, the
reverse mode (``force_curve`` and its gradient) and a ``vmap`` batch. For each scene: the accepted
and rejected steps of both revisions, whether every array is bitwise identical, and otherwise the
largest difference relative to the array's largest value (where B's mesh holds A's nodes and
more, a padded mesh, the profiles on A's nodes); the force read at 201 fixed times through each
run's interpolant, an answer apart from the steps taken; and the bytes of the loop's state,
what reverse mode stores per attempt. Exits 1 if any scene differs in its step counts or by more
than ``--limit`` (default 1e-12), or if B's state is larger. Writes
benchmarks/out/same_answers.md.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import numpy as np

# The child runs as a plain script under another revision's tree (PYTHONPATH), where benchmarks
# may differ or be missing: it imports nothing of benchmarks, the parent alone does.
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _scenes(quick: bool):
    """name -> a function of the lubjax module returning a dict of arrays (step counts included)."""
    import jax
    import jax.numpy as jnp

    def run(beta, z0, t_end, **kw):
        def f(lj):
            settings = lj.Settings(**kw.pop("settings", {}))
            res = lj.relax(beta, z0, t_end, settings=settings, check="flag", **kw)
            out = {k: getattr(res, k) for k in ("t", "force", "film_min", "film_center", "gap",
                                                  "velocity", "outflow", "elastic_energy",
                                                  "dissipation", "force_error")}
            out["profiles"] = res.pressure
            out["films"] = res.film
            out["nodes"] = res.r
            # the answer apart from the steps taken: the run's interpolant at fixed times
            out["force at fixed times"] = res.at(np.linspace(res.t[0], t_end, 201))
            out["steps"] = np.array([res.accepted, res.rejected])
            return out
        return f

    def sampled(lj):
        tau = 0.05 / 1.26
        s = np.linspace(0.0, 0.01, 2001)
        return lj.SampledTravel(s, s - tau * (1 - np.exp(-s / tau)), breakpoints=(0.0,))

    def with_drive(make, beta, z0, t_end, **kw):
        def f(lj):
            kw2 = dict(kw)
            if "substrate" in kw2 and callable(kw2["substrate"]):
                kw2["substrate"] = kw2["substrate"](lj)
            return run(beta, z0, t_end, drive=make(lj) if make else None, **kw2)(lj)
        return f

    def layer(lj):
        return lj.Layer(9.96)

    def visco(lj):
        return lj.Viscoelastic.standard_linear_solid(3.0, 0.5)

    def reverse(lj):
        plan = lj.make_plan(5.0, settings=lj.Settings(rtol=1e-3, max_steps=1500),
                            times=np.linspace(0.05, 5.0, 40))
        curve = lj.force_curve(plan, 100.0, 0.5)
        grad = jax.grad(lambda b, z: jnp.sum(lj.force_curve(plan, b, z)), argnums=(0, 1))(
            100.0, 0.5)
        return {"curve": np.asarray(curve), "grad": np.asarray(grad)}

    def batch(lj):
        res = lj.sweep([10.0, 1000.0], [0.5, 1.5], 5.0, settings=lj.Settings(rtol=1e-3),
                       devices=1, batching="vmap")
        return {"force": np.asarray(res.force), "film_min": np.asarray(res.film_min)}

    def state_bytes(lj):
        """Bytes of the loop's state, what reverse mode stores per attempt (N = 200 nodes, no
        profiles): elastic and viscoelastic, orders 2 and 3."""
        import importlib

        here = os.path.dirname(lj.__file__)
        for name in ("_loop", "_rollout", "_stepper"):  # where the loop lived, newest first
            # (by file: the editable install would import a module this revision lacks)
            if os.path.exists(os.path.join(here, name + ".py")):
                loop = importlib.import_module("lubjax." + name)
                if hasattr(loop, "initial_state") or hasattr(loop, "_initial_state"):
                    break
        initial_state = getattr(loop, "initial_state", None) or loop._initial_state
        toolkit = getattr(lj, "stepper", lj)  # (older revisions export it at the top level)
        disc = toolkit.discretise(lj.uniform_mesh(0.05, 10.0))
        out = []
        for substrate in (lj.HalfSpace(), visco(lj)):
            for order in (2, 3):
                tol = toolkit.Tolerance(order=order)
                if hasattr(loop, "Inputs"):  # the loop's inputs in one record
                    def initial(s, t):
                        return initial_state(loop.Inputs(
                            disc, 100.0, 0.5, lj.Travel(), s, 1.0, t, jnp.zeros((0,))))
                else:
                    def initial(s, t):
                        return initial_state(disc, 100.0, lj.Travel(), s, 0.5, t,
                                                   jnp.zeros((0,)))
                shape = jax.eval_shape(initial, substrate, tol)
                out.append(sum(x.size * x.dtype.itemsize for x in jax.tree_util.tree_leaves(
                    shape)))
        return {"state_bytes": np.array(out)}

    noest = {"error_estimate": False}
    scenes = {
        "loop state bytes (elastic o2, o3; viscoelastic o2, o3)": state_bytes,
        "default relax(100, 0.5, 5), estimate on": run(100.0, 0.5, 5.0, profile_times=[0.5, 2.0]),
        "order 1, relax(100, 0.5, 5)": run(100.0, 0.5, 5.0, settings={"order": 1, **noest}),
        "order 3, relax(100, 0.5, 5)": run(100.0, 0.5, 5.0, settings={"order": 3, **noest},
                                           profile_times=[0.5, 2.0]),
        "order 3, relax(1000, 2, 50)": run(1000.0, 2.0, 50.0, settings={"order": 3, **noest}),
        "load (creep), order 2": with_drive(lambda lj: lj.Load(), 100.0, 1.0, 5.0,
                                            settings=noest),
        "load (creep), order 3": with_drive(lambda lj: lj.Load(), 100.0, 1.0, 5.0,
                                            settings={"order": 3, **noest}),
        "spring, order 2": with_drive(lambda lj: lj.Spring(2.0), 100.0, 0.5, 5.0, settings=noest),
        "spring, order 3": with_drive(lambda lj: lj.Spring(2.0), 100.0, 0.5, 5.0,
                                      settings={"order": 3, **noest}),
        "free sphere, order 2": with_drive(
            lambda lj: lj.FreeSphere(inverse_mass=50.0, weight=0.1), 10.0, 1.0, 6.0,
            settings=noest),
        "free sphere, order 3": with_drive(
            lambda lj: lj.FreeSphere(inverse_mass=50.0, weight=0.1), 10.0, 1.0, 6.0,
            settings={"order": 3, **noest}),
        "sampled smooth start on a layer": with_drive(sampled, 41.4, 1.11, 0.01,
                                                      substrate=layer, settings=noest),
        "layer, order 3": with_drive(None, 100.0, 0.5, 5.0, substrate=layer,
                                     settings={"order": 3, **noest}),
        "viscoelastic, order 2": with_drive(None, 100.0, 0.5, 5.0, substrate=visco,
                                            settings=noest),
        "viscoelastic, order 3": with_drive(None, 100.0, 0.5, 5.0, substrate=visco,
                                            settings={"order": 3, **noest}),
        "reverse mode: force_curve and grad": reverse,
        "vmap batch (sweep)": batch,
    }
    if not quick:
        for beta in (1.0, 10.0, 100.0, 1000.0):
            for z0 in (0.5, 0.9, 1.0, 1.11, 2.0):
                scenes[f"accuracy case beta={beta:g}, z0={z0:g}, t=1e3"] = run(
                    beta, z0, 1e3, settings=noest)
    return scenes


def child(out_path: str, quick: bool) -> None:
    import lubjax

    print(f"lubjax from {os.path.dirname(lubjax.__file__)}", file=sys.stderr, flush=True)
    arrays = {}
    for i, (name, fn) in enumerate(_scenes(quick).items()):
        print(f"  [{i + 1}] {name}", file=sys.stderr, flush=True)
        for key, value in fn(lubjax).items():
            arrays[f"{name}::{key}"] = np.asarray(value)
    np.savez(out_path, **arrays)


def _run_child(tree: str, out_path: str, quick: bool) -> None:
    cmd = [sys.executable, os.path.abspath(__file__), "--child", out_path]
    if quick:
        cmd.append("--quick")
    env = dict(os.environ, PYTHONPATH=tree)
    subprocess.run(cmd, cwd=tempfile.gettempdir(), env=env, check=True)


def _shared_nodes(r_a, r_b):
    """Where A's mesh nodes sit in B's (an index array), when B's mesh contains every node of
    A's; else None."""
    if r_a is None or r_b is None:
        return None
    where = np.searchsorted(r_b, r_a)
    if where.max(initial=0) >= r_b.size or not np.array_equal(r_b[where], r_a):
        return None
    return where


def compare(a: dict, b: dict, limit: float) -> tuple[list[str], bool]:
    names = sorted({k.split("::")[0] for k in a}, key=list({k.split("::")[0]: 0
                                                              for k in a}).index)
    lines = ["| scene | steps A (acc, rej) | steps B | bitwise | largest difference / max | "
             "force at fixed times / max |", "|---|---|---|---|---|---|"]
    ok = True
    for name in names:
        keys = [k for k in a if k.startswith(name + "::")]
        if keys == [name + "::state_bytes"]:  # a cost, not an answer: B must be no larger
            x, y = a[keys[0]], b.get(keys[0])
            smaller = y is not None and x.shape == y.shape and bool(np.all(y <= x))
            ok &= smaller
            lines.append(f"| {name} | {', '.join(map(str, x))} | "
                         f"{'—' if y is None else ', '.join(map(str, y))} | — | "
                         f"{'B no larger' if smaller else 'B LARGER'} |")
            continue
        same, worst, where, fixed = True, 0.0, "", "—"
        on_nodes_of_a = _shared_nodes(a.get(name + "::nodes"), b.get(name + "::nodes"))
        for k in keys:
            x, y = a[k], b.get(k)
            if on_nodes_of_a is not None and y is not None and y.shape[-1:] != x.shape[-1:]:
                # B's mesh holds A's nodes and more (a padded mesh): compare on A's nodes
                y = np.take(y, on_nodes_of_a, axis=-1)
            if y is None or x.shape != y.shape:
                same, worst, where = False, np.inf, k.split("::")[1] + " (shape)"
                continue
            if np.array_equal(x, y, equal_nan=True):
                if k.endswith("::force at fixed times"):
                    fixed = "0"
                continue
            same = False
            scale = np.nanmax(np.abs(x)) if np.any(np.isfinite(x)) else 1.0
            diff = np.nanmax(np.abs(x - y)) / (scale if scale > 0 else 1.0)
            if k.endswith("::force at fixed times"):
                fixed = f"{diff:.1e}"
            if not diff <= worst:
                worst, where = diff, k.split("::")[1]
        sa = a.get(name + "::steps")
        sb = b.get(name + "::steps")
        steps_a = "—" if sa is None else f"{sa[0]}, {sa[1]}"
        steps_b = "—" if sb is None else f"{sb[0]}, {sb[1]}"
        same_steps = sa is None or (sb is not None and np.array_equal(sa, sb))
        ok &= same_steps and (same or worst <= limit)
        diff_cell = "0" if same else f"{worst:.2e} ({where})"
        if on_nodes_of_a is not None and on_nodes_of_a.size != b[name + "::nodes"].size:
            diff_cell += (f"; nodes {on_nodes_of_a.size} → {b[name + '::nodes'].size}, "
                          "compared on A's")
        lines.append(f"| {name} | {steps_a} | {steps_b} | {'yes' if same else 'no'} | "
                     f"{diff_cell} | {fixed} |")
    return lines, ok


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--child"]:
        child(argv[1], "--quick" in argv[2:])
        return 0
    from benchmarks import _harness

    ap = _harness.parser(__doc__)
    ap.add_argument("rev_a", nargs="?")
    ap.add_argument("rev_b", nargs="?", default=None, help="default: the working tree")
    ap.add_argument("--quick", action="store_true", help="skip the accuracy table's 20 cases")
    ap.add_argument("--limit", type=float, default=1e-12)
    args = _harness.parse(ap, argv)
    if not args.rev_a:
        ap.error("give the revision to compare with (e.g. HEAD)")

    with tempfile.TemporaryDirectory() as tmp:
        results = {}
        for label, rev in (("A", args.rev_a), ("B", args.rev_b)):
            tree = ROOT
            if rev is not None:
                tree = os.path.join(tmp, label)
                subprocess.run(["git", "-C", ROOT, "worktree", "add", "-q", "--detach", tree,
                                rev], check=True)
            try:
                print(f"{label}: {rev or 'working tree'}", file=sys.stderr, flush=True)
                path = os.path.join(tmp, f"{label}.npz")
                _run_child(tree, path, args.quick)
                results[label] = dict(np.load(path))
            finally:
                if rev is not None:
                    subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", tree],
                                   check=False)
    lines, ok = compare(results["A"], results["B"], args.limit)
    command = "python -m benchmarks.same_answers " + " ".join(
        x for x in (args.rev_a, args.rev_b) if x) + (" --quick" if args.quick else "")
    header = [f"# Same answers: A = {args.rev_a}, B = {args.rev_b or 'the working tree'}", "",
              f"`{command}`: every array of every scene compared; the last column is the "
              "largest |A - B| over the array's largest |A| (and which array).", ""]
    _harness.write_report(os.path.join(_harness.OUT, "same_answers.md"), header + lines)
    print("SAME" if ok else "DIFFERENT", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

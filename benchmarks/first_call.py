"""A fresh process's first ``relax(100, 0.5, 5)`` at each git revision given, with that
revision's defaults: what a user waits for, measured side by side in one run.

    python -m benchmarks.first_call f1635a7 6c71a6e HEAD [--repeat 5] [--t-end 1e6] [--no-estimate]

Issue "Error control", item 8 asks for no slower than "today's 0.16 s run / 0.9 s compile": the
hand-tuned grid of commit f1635a7 (before the error-controlled stepper), measured on another
machine. Machines differ (the same code's compile took 0.9 s there and 1.5–1.9 s on a later VM),
so this runs that revision and others on *this* machine, alternating: each revision is checked
out into a temporary git worktree and imported from there in fresh processes (``--repeat`` each,
round-robin). Columns: import time, ``Result.compile_s`` of the first call, the first call's
wall time, the median ``run_s`` of five further calls, and the accepted steps. Writes
benchmarks/out/first_call.md; ``--t-end`` runs ``relax(100, 0.5, t_end)`` instead (a long hold:
the steps the neck's thinning costs) and writes benchmarks/out/first_call_t<t_end>.md.
``--family`` times a family instead: ``relax(β, z̄0, 5)`` at defaults for β = 10⁻¹…10⁹ (one per
decade) and z̄0 = 0.1, 0.5, 2 in one fresh process, as a user's loop over β would call it; columns:
the runs, their distinct mesh sizes, the calls that compiled, the compile and run seconds summed,
and the loop's wall time. It writes benchmarks/out/first_call_family.md.
``--no-estimate`` passes ``Settings(error_estimate=False)`` to revisions that have that setting
(the hand-tuned grid has no estimate to switch off): the stepper's own program against the grid's,
without the estimate's coarse-mesh program; it writes benchmarks/out/first_call_noestimate.md.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

from benchmarks import _harness
from benchmarks._harness import OUT, ROOT

CHILD = r"""
import json, sys, time
t_end = float(sys.argv[1])
no_estimate = sys.argv[2] == "1"
start = time.perf_counter()
import lubjax
imported = time.perf_counter()
fields = getattr(lubjax.Settings, "__dataclass_fields__", {})
kw = dict(settings=lubjax.Settings(error_estimate=False)) if (
    no_estimate and "error_estimate" in fields) else {}
first = lubjax.relax(100, 0.5, t_end, **kw)
done = time.perf_counter()
runs = sorted(lubjax.relax(100, 0.5, t_end, **kw).run_s for _ in range(5))
print(json.dumps(dict(import_s=imported - start, compile_s=first.compile_s,
                      first_call_s=done - imported, run_s=runs[2],
                      steps=int(getattr(first, "accepted", -1)))))
"""

FAMILY_CHILD = r"""
import json, sys, time
import lubjax
start = time.perf_counter()
runs = [lubjax.relax(10.0 ** k, z0, 5.0) for z0 in (0.1, 0.5, 2.0) for k in range(-1, 10)]
wall = time.perf_counter() - start
print(json.dumps(dict(runs=len(runs), sizes=len({r.r.size for r in runs}),
                      compiled=sum(r.compile_s > 0 for r in runs),
                      compile_s=sum(r.compile_s for r in runs),
                      run_s=sum(r.run_s for r in runs), wall_s=wall)))
"""


def main(argv=None):
    from benchmarks._harness import label, median_range, write_report

    ap = _harness.parser(__doc__)
    ap.add_argument("revisions", nargs="+")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--t-end", type=float, default=5.0)
    ap.add_argument("--no-estimate", action="store_true",
                    help="Settings(error_estimate=False) where the revision has it")
    ap.add_argument("--family", action="store_true",
                    help="a loop of relax over beta and z0 instead of one call")
    args = _harness.parse(ap, argv)
    child = [FAMILY_CHILD] if args.family else [CHILD, repr(args.t_end),
                                                 "1" if args.no_estimate else "0"]
    results = {rev: [] for rev in args.revisions}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {}
        for rev in args.revisions:
            tree = os.path.join(tmp, rev.replace("/", "_"))
            subprocess.run(["git", "-C", ROOT, "worktree", "add", "-q", "--detach", tree, rev],
                           check=True)
            trees[rev] = tree
        try:
            for i in range(args.repeat):
                for rev, tree in trees.items():
                    proc = subprocess.run([sys.executable, "-c", *child], cwd=tree,
                                          env=dict(os.environ, PYTHONPATH=tree),
                                          capture_output=True, text=True, check=True)
                    results[rev].append(json.loads(proc.stdout.strip().splitlines()[-1]))
                    print(f"{rev} #{i + 1}: {results[rev][-1]}", file=sys.stderr, flush=True)
        finally:
            for tree in trees.values():
                subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", tree],
                               check=False)
    if args.family:
        return _family_report(args, results)
    keys = ("import_s", "compile_s", "first_call_s", "run_s")
    default = args.t_end == 5.0
    command = f"python -m benchmarks.first_call {' '.join(args.revisions)} --repeat {args.repeat}"
    if not default:
        command += f" --t-end {args.t_end:g}"
    if args.no_estimate:
        command += " --no-estimate"
    lines = [
        f"# A fresh process's first relax(100, 0.5, {args.t_end:g}), by revision ({label()})",
        "",
        f"`{command}`: "
        + ("each revision's defaults but Settings(error_estimate=False) where it exists"
           if args.no_estimate else "each revision's own defaults")
        + ", fresh processes alternating between revisions; median (min–max) in seconds.",
        "",
        "| revision | import | compile_s | first call | run_s (median of 5 calls) | steps |",
        "|---|---|---|---|---|---|",
    ]
    for rev, rows in results.items():
        cells = [median_range(r[k] for r in rows) for k in keys]
        cells.append(str(rows[0]["steps"]))
        lines.append(f"| {rev} | " + " | ".join(cells) + " |")
    name = "first_call" + ("" if default else f"_t{args.t_end:g}")
    name += "_noestimate.md" if args.no_estimate else ".md"
    write_report(os.path.join(OUT, name), lines)


def _family_report(args, results):
    from benchmarks._harness import label, median_range, write_report

    command = (f"python -m benchmarks.first_call {' '.join(args.revisions)} "
               f"--repeat {args.repeat} --family")
    lines = [
        f"# A loop of relax(beta, z0, 5) over a family, by revision ({label()})",
        "",
        f"`{command}`: beta = 1e-1..1e9 (one per decade) × z0 = 0.1, 0.5, 2 at each revision's "
        "defaults, in one fresh process; fresh processes alternate between revisions; median "
        "(min–max) in seconds.",
        "",
        "| revision | runs | mesh sizes | calls that compiled | compile_s | run_s | loop wall |",
        "|---|---|---|---|---|---|---|",
    ]
    for rev, rows in results.items():
        first = rows[0]
        cells = [str(first[k]) for k in ("runs", "sizes", "compiled")]
        cells += [median_range(r[k] for r in rows) for k in ("compile_s", "run_s", "wall_s")]
        lines.append(f"| {rev} | " + " | ".join(cells) + " |")
    write_report(os.path.join(OUT, "first_call_family.md"), lines)


if __name__ == "__main__":
    main()

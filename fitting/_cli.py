"""``lubjax-fit TRACE.csv [more.csv ...] --out fit.json --plot fit.png``: fit E*, η, z0.

Prints one summary line per trace to stdout, a progress line to stderr while it works, writes
the JSON (one object for one trace, a list for several), optionally a CSV table and the plot(s).

Every output is checked before the traces are read (writable, not an input trace, not another
output, a known plot format) and written atomically. Every failure is one line on stderr: exit
status 2 for bad usage or input, 1 for a fit that did not converge or an output that could not
be written (``--debug`` shows the traceback).
"""

from __future__ import annotations

import csv
import json
import os
import sys
import time

from lubjax._files import (
    EXIT_EPILOG,
    EXIT_FAILED,
    EXIT_OK,
    Parser,
    UsageError,
    add_debug_flag,
    atomic_open,
    check_distinct_inputs,
    check_outputs,
    plot_format,
    positive_int,
    prepare_outputs,
    run_cli,
    save_figure,
)

from ._fit import FitResult, fit_traces, result_to_dict
from ._io import read_trace

PROG = "lubjax-fit"


def _fmt(value, err, unit, scale=1.0):
    return f"{value / scale:.4g} ± {err / scale:.2g} {unit}"


def summary_line(res: FitResult) -> str:
    status = "converged" if res.converged else "NOT CONVERGED"
    if not res.identifiable:
        status += ", NOT IDENTIFIABLE"
    return (
        f"{os.path.basename(res.name) or 'trace'}: "
        f"E* = {_fmt(res.E_star, res.stderr['E_star'], 'MPa', 1e6)}, "
        f"eta = {_fmt(res.viscosity, res.stderr['viscosity'], 'Pa s')}, "
        f"z0 = {_fmt(res.z0, res.stderr['z0'], 'um', 1e-6)}; beta = {res.beta:.4g}, "
        f"z0/dc = {res.z0_over_dc:.4g}, rms residual = {res.rms_residual:.3g} N; "
        f"{status} ({res.n_iterations} iterations, {res.wall_s:.1f} s)"
    )


def plot_fit(res: FitResult, path: str) -> None:
    """Data and model, residuals, and the fitted values with their 1-σ errors.

    Written atomically in the format of ``path``'s extension (png, pdf, svg, ...)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(9, 7.5))
    gs = fig.add_gridspec(3, 1, height_ratios=[3, 1.3, 1.1], hspace=0.35)
    ax = fig.add_subplot(gs[0])
    ax.plot(res.time, res.force * 1e3, ".", ms=2.5, color="0.55", label="data")
    ax.plot(res.time, res.model * 1e3, "-", color="C3", lw=1.5, label="lubjax model (fit)")
    ax.set_ylabel("force [mN]")
    ax.set_title(os.path.basename(res.name) or "trace")
    ax.legend(loc="upper right")
    ax.grid(alpha=0.3)
    ax2 = fig.add_subplot(gs[1], sharex=ax)
    resid = (res.force - res.model) * 1e3
    ax2.plot(res.time, resid, ".", ms=2.5, color="C0")
    ax2.axhline(0.0, color="k", lw=0.8)
    ax2.set_ylabel("data - model [mN]")
    ax2.set_xlabel("time [s]")
    ax2.grid(alpha=0.3)
    ax3 = fig.add_subplot(gs[2])
    ax3.axis("off")
    se = res.stderr
    lines = [
        f"E* = {res.E_star / 1e6:.4g} ± {se['E_star'] / 1e6:.2g} MPa     "
        f"η = {res.viscosity:.4g} ± {se['viscosity']:.2g} Pa·s     "
        f"z0 = {res.z0 * 1e6:.4g} ± {se['z0'] * 1e6:.2g} μm",
        f"β = {res.beta:.4g}    z0/dc = {res.z0_over_dc:.4g}    dc = {res.indent * 1e6:.4g} μm    "
        f"v0 = {res.speed * 1e3:.4g} mm/s    R = {res.radius * 1e3:.4g} mm    "
        f"offset = {res.offset * 1e3:.3g} ± {se['offset'] * 1e3:.2g} mN",
        f"rms residual = {res.rms_residual * 1e3:.3g} mN    "
        f"{'converged' if res.converged else 'NOT converged'}"
        f"{'' if res.identifiable else ', NOT identifiable'}    {res.n_iterations} iterations"
        f" ({res.method})",
    ]
    truth = []
    for label, key, val, scale, unit in [
        ("E*", "true_E_star_Pa", res.E_star, 1e6, "MPa"),
        ("η", "true_viscosity_Pa_s", res.viscosity, 1.0, "Pa·s"),
        ("z0", "true_z0_m", res.z0, 1e-6, "μm"),
    ]:
        try:
            true = float(res.metadata[key])
        except (KeyError, ValueError):
            continue
        truth.append(f"{label} true {true / scale:.4g} {unit} ({100 * (val / true - 1):+.2f} %)")
    if truth:
        lines.append("synthetic truth: " + ",  ".join(truth))
    for i, text in enumerate(lines):
        ax3.text(0.0, 1.0 - 0.27 * i, text, transform=ax3.transAxes, va="top", fontsize=9.5)
    try:
        save_figure(fig, path, dpi=120, bbox_inches="tight")
    finally:
        plt.close(fig)


def plot_paths(plot: str, traces) -> list[str]:
    """One plot file per trace: ``plot`` itself for one trace, else ``<stem>_<trace><ext>``.

    Traces with the same file name in different folders are told apart by their path relative
    to the folder they share (``fits_a_run.png``, ``fits_b_run.png``); should names still clash,
    they are numbered. No two traces get the same plot file.
    """
    if len(traces) == 1:
        return [plot]
    stem, ext = os.path.splitext(plot)
    names = [os.path.splitext(os.path.basename(p))[0] or "trace" for p in traces]
    if len(set(names)) < len(names):
        full = [os.path.abspath(p) for p in traces]
        common = os.path.commonpath([os.path.dirname(p) for p in full])
        names = [os.path.splitext(os.path.relpath(p, common))[0].replace(os.sep, "_") for p in full]
    if len(set(names)) < len(names):
        names = [f"{k}_{name}" for k, name in enumerate(names, start=1)]
    return [f"{stem}_{name}{ext}" for name in names]


def write_table(results, path: str) -> None:
    """One CSV row per trace with the fitted values, errors and flags (written atomically)."""
    cols = [
        "trace",
        "E_star_Pa",
        "E_star_se",
        "viscosity_Pa_s",
        "viscosity_se",
        "z0_m",
        "z0_se",
        "offset_N",
        "beta",
        "z0_over_dc",
        "rms_residual_N",
        "converged",
        "identifiable",
        "n_iterations",
        "wall_s",
    ]
    with atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in results:
            w.writerow(
                [
                    r.name,
                    r.E_star,
                    r.stderr["E_star"],
                    r.viscosity,
                    r.stderr["viscosity"],
                    r.z0,
                    r.stderr["z0"],
                    r.offset,
                    r.beta,
                    r.z0_over_dc,
                    r.rms_residual,
                    r.converged,
                    r.identifiable,
                    r.n_iterations,
                    r.wall_s,
                ]
            )


def build_parser() -> Parser:
    p = Parser(
        prog=PROG,
        description="Fit the substrate modulus E*, film viscosity eta and initial gap z0 to "
        "relaxation traces (CSV: see data/README.md) with the lubjax soft-EHL solver.",
        epilog=EXIT_EPILOG.format(
            failed="a fit did not converge (its results are still written),\n"
            "     or an output could not be written"
        ),
    )
    p.add_argument("traces", nargs="+", help="trace CSV file(s)")
    p.add_argument("--out", help="JSON output (one object, or a list for several traces)")
    p.add_argument("--table", help="also write a CSV table, one row per trace")
    p.add_argument(
        "--plot",
        help="figure of data, model, residuals and values (.png, .pdf, .svg, ...; one per "
        "trace: the trace name is appended when there are several)",
    )
    p.add_argument(
        "--method",
        choices=("lm", "lbfgs"),
        default="lm",
        help="optimiser: Levenberg-Marquardt (default) or optax L-BFGS",
    )
    p.add_argument("--no-offset", action="store_true", help="do not fit a constant force offset")
    p.add_argument("--max-iter", type=positive_int, default=60, help="iteration limit (default 60)")
    p.add_argument("--quiet", action="store_true", help="no progress line on stderr")
    add_debug_flag(p)
    return p


def _run(args) -> int:
    check_distinct_inputs(args.traces, "trace")
    plots = []
    if args.plot is not None:
        if not args.plot.strip():
            raise UsageError("--plot: empty file name")
        plot_format(args.plot)  # before the per-trace names, so the message shows the user's
        plots = plot_paths(args.plot, args.traces)
    outputs = [("--out", args.out), ("--table", args.table)] + [("--plot", p) for p in plots]
    check_outputs(outputs, inputs=args.traces, input_label="input trace")
    start = time.perf_counter()
    shown = False

    def progress(msg):
        nonlocal shown
        if not args.quiet:
            shown = True
            elapsed = time.perf_counter() - start
            sys.stderr.write(f"\r\033[K[{elapsed:6.1f} s] {msg}"[:200])
            sys.stderr.flush()

    try:
        traces = [read_trace(path) for path in args.traces]
        prepare_outputs(outputs)  # creates missing folders: only once the inputs are good
        progress(f"read {len(traces)} trace(s); compiling the solver (first call only) ...")
        results = fit_traces(
            traces,
            method=args.method,
            fit_offset=not args.no_offset,
            max_iter=args.max_iter,
            progress=progress,
        )
    finally:
        if shown:  # clear the progress line: an error message or the summary follows
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()
    for res in results:
        print(summary_line(res))
        for flag in res.flags[1:]:
            print(f"  warning: {flag}")
    dicts = [result_to_dict(r) for r in results]
    if args.out:
        with atomic_open(args.out, "w") as fh:
            json.dump(dicts[0] if len(dicts) == 1 else dicts, fh, indent=2)
        print(f"wrote {args.out}")
    if args.table:
        write_table(results, args.table)
        print(f"wrote {args.table}")
    for res, path in zip(results, plots):
        plot_fit(res, path)
        print(f"wrote {path}")
    return EXIT_OK if all(r.converged for r in results) else EXIT_FAILED


def main(argv=None) -> int:
    """Run ``lubjax-fit`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    return run_cli(PROG, build_parser(), _run, argv)


if __name__ == "__main__":
    sys.exit(main())

"""``lubjax-fit TRACE.csv [more.csv ...] --out fit.json --plot fit.png``: fit E*, η, z0.

Prints one summary line per trace to stdout, a progress line to stderr while it works, writes
the JSON (one object for one trace, a list for several), optionally a CSV table and the plot(s).
Starting values outside soft lubricated contact (:mod:`fitting._checks`: a column in the wrong
unit) are warned about on stderr before the fit, and flagged in every output after it.

Every output is checked before the traces are read (writable, not an input trace, not another
output, a known plot format) and written atomically. Every failure is one line on stderr: exit
status 2 for bad usage or input, 1 for a fit that did not converge or an output that could not
be written (``--debug`` shows the traceback).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import sys
import textwrap
import time

from lubjax._fitting_api import UsageError
from lubjax._fitting_api import cli_options as _options
from lubjax._fitting_api import files as _files

from . import _afm
from ._cache import enable_compilation_cache
from ._checks import e_star_range, plausibility_flags
from ._columns import parse_columns, parse_units
from ._compare import compare_models
from ._csv import read_trace
from ._figure import plot_fit
from ._fit import fit_traces
from ._model import FIT_SETTINGS, ModelSpec
from ._optimisers import METHODS
from ._report import fit_report, result_to_dict, summary_line, write_table
from ._scales import common_drive
from ._start import scales_and_starts
from ._trace import DRIVES

PROG = "lubjax-fit"
SHAREABLE = ("E_star", "viscosity", "z0", "stiffening", "relaxation_time")
TRACE_FORMAT = """

trace files: delimited text (UTF-8), '# key: value' lines, a header row, numbers:
  # radius_m: 2.0e-3
  time_s,displacement_m,force_N
  0.0,0.0,0.0012
  ...
metadata lines:
  # radius_m:         the sphere radius R [m] (required; or the reduced radius)
  # poisson_ratio:    optional: the JSON then also gives E = E*(1 - nu^2)
  # drive:            optional: travel (default), spring or force (--drive)
  # stiffness_N_m:    optional: the load cell's stiffness k [N/m] (spring)
  other keys are kept in the JSON; '# text' without a colon is a comment
columns (any order; other columns only with --columns):
  time_s              time [s], strictly increasing
  displacement_m      the stage's travel toward the substrate since the first
                      row [m] (under --drive force: the sphere's approach)
  force_N             the normal force [N], positive when pushing back (under
                      --drive force: the prescribed load)
The full description: the trace file format page of the documentation,
docs/guide/trace-format.md."""
#: Runnable examples ending --help (the data/ folder of the lubjax sources holds these traces).
EXAMPLES = (
    "lubjax-fit data/paper_dc140.csv --out fit.json --plot fit.png",
    "lubjax-fit data/paper_dc126.csv data/paper_dc140.csv data/paper_dc154.csv "
    "--shared E_star,viscosity --out joint.json --report joint.txt",
    "lubjax-fit data/visco_dc140.csv --compare --rtol 1e-3 --report compare.txt",
)


def _epilog() -> str:
    """The exit statuses, the trace format, then runnable examples (the end of --help)."""
    exits = _files.EXIT_EPILOG.format(failed="a fit did not converge (its results are still "
                                      "written),\n     or an output could not be written")
    examples = "\n".join(f"  {_options.example_lines(line)}" for line in EXAMPLES)
    return (f"{exits}{TRACE_FORMAT}\n\nexamples (data/ of the lubjax sources holds these "
            f"traces):\n{examples}")


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


def build_parser() -> _files.Parser:
    p = _files.Parser(
        prog=PROG,
        description="Fit the substrate modulus E*, film viscosity eta and initial gap z0 (and,\n"
        "for a viscoelastic solid, E0/Einf and tau) to tribometer traces with the lubjax\n"
        "soft-EHL solver.\n\n"
        "A trace is delimited text (',', ';', tabs or spaces; decimal commas with ';' or tabs)\n"
        "with the sphere radius on a line '# radius_m: 2e-3' before the header row\n"
        "'time_s,displacement_m,force_N': time, travel toward the substrate since the first\n"
        "row, force (positive when pushed back). Other exports: --columns maps their cells,\n"
        "--units declares units (or a '# units: force=mN' line, or '(mN)' in a header cell),\n"
        "lines before the header row are skipped. The trace file format page of the\n"
        "documentation (docs/guide/trace-format.md) has it all.",
        epilog=_epilog(),
    )
    for add in (_add_trace_options, _add_model_options, _add_output_options, _add_fit_options):
        add(p)
    _options.add_debug_flag(p)
    return p


def _add_trace_options(p) -> None:
    """The traces and how to read them (exports, units, vendor files)."""
    p.add_argument("traces", nargs="+", help="trace file(s)")
    p.add_argument("--columns", help="which cells hold the trace, by header name or number "
                   "(from 1): 'time=Time (s),displacement=Piezo (nm),force=Load (uN)' or "
                   "'time=1,displacement=2,force=3' (a file without a header row); other cells "
                   "are ignored, a unit in brackets in the header is the column's unit")
    p.add_argument("--units", help="units of the columns, converted to SI on reading, e.g. "
                   "force=mN,time=ms,displacement=um; time s|ms|us, displacement m|mm|um|nm, "
                   "force N|mN|uN|nN (µ accepted); over a '# units:' line and the header's")
    p.add_argument("--force-sign", type=int, choices=(1, -1), default=1,
                   help="-1: the instrument records compression as negative force; flip it")
    afm = p.add_argument_group(
        "AFM and indenter vendor files (JPK .jpk-force/.jpk-force-map/.jpk-qi-*, Asylum .ibw, "
        "Optics11 Chiaro .txt, afmformats .h5/.tab; pip install lubjax[afm])",
        "the cantilever is the spring drive (k from the file), the height the stage; the "
        "retract is not fitted: adhesion and cavitation are not modelled")
    afm.add_argument("--radius", type=_options.positive_float,
                     help="tip (sphere) radius R [m], over the file's (required where the file "
                     "gives none: JPK, Igor)")
    afm.add_argument("--poisson", type=float, help="Poisson ratio of the sample (for E from E*)")
    afm.add_argument("--segments", default="approach",
                     help="segments fitted, comma-separated: approach (default), dwell (a "
                     "constant-height or constant-force hold); with --drive force: "
                     "approach,dwell of a constant-force dwell, fitted as creep. The retract "
                     "is refused (adhesion, cavitation: not modelled)")
    afm.add_argument("--baseline", choices=_afm.BASELINES, default="offset",
                     help="force baseline removed before contact: offset (median, default; the "
                     "fit still fits an offset) or tilt (a line in the travel)")
    afm.add_argument("--curve", type=int, action="append",
                     help="curve index of a force map (repeatable; default: every curve)")
    afm.add_argument("--max-samples", type=_options.positive_int, default=_afm.MAX_SAMPLES,
                     help=f"decimate each curve to this many samples by block means (default "
                     f"{_afm.MAX_SAMPLES})")


def _add_model_options(p) -> None:
    """What is fitted: drive, substrate, fixed and shared parameters, model comparison."""
    p.add_argument("--fix", action="append", metavar="NAME=VALUE",
                   help="hold a parameter at a known value in SI units instead of fitting it, "
                   "e.g. --fix viscosity=1e-3 (names: E_star, viscosity, z0, stiffening, "
                   "relaxation_time, offset); repeat or separate with commas")
    p.add_argument(
        "--drive", choices=DRIVES, default=None,
        help="what the instrument prescribes: travel (position control; default), force (load "
        "control: displacement is the response) or spring (travel through a load cell of "
        "stiffness '# stiffness_N_m:'); default: the trace's '# drive:' header, else spring "
        "when it gives a stiffness, else travel",
    )
    _options.add_substrate_options(p.add_argument_group("substrate", textwrap.fill(
        "A layer of known thickness on a rigid base, or a viscoelastic half-space: one Prony "
        "term, E0/Einf and tau fitted.", 76)))
    _options.add_indenter_option(p)
    p.add_argument("--compare", action="store_true",
                   help="also fit the other model and report which one the data ask for "
                   "(likelihood ratio, AIC, BIC): with --substrate layer the half-space "
                   "against the layer, otherwise the half-space against a viscoelastic solid")
    p.add_argument("--shared", help="joint fit: parameters shared by all traces, e.g. "
                   "E_star,viscosity (the others, and the offsets, are fitted per trace)")
    p.add_argument("--no-offset", action="store_true", help="do not fit a constant offset")


def _add_output_options(p) -> None:
    p.add_argument("--out", help="JSON output (one object, or a list for several traces)")
    p.add_argument("--table", help="also write a CSV table, one row per trace")
    p.add_argument(
        "--plot",
        help="figure of data, model, residuals and the fit report (.png, .pdf, .svg, ...; one "
        "per trace: the trace name is appended when there are several)",
    )
    p.add_argument("--report", help="also write the text fit report(s) to this file")


def _add_fit_options(p) -> None:
    """The optimiser, the noise model and the solver's accuracy."""
    p.add_argument("--method", choices=METHODS, default="lm",
                   help="optimiser: Levenberg-Marquardt (default), trf (scipy least_squares) "
                   "or lbfgs (optax; it can need a tighter --rtol: a smoother model)")
    p.add_argument("--noise", choices=("auto", "white", "ar1"), default="auto",
                   help="noise model of the errors: auto (AR(1) when the residuals are not "
                   "white; default), white, ar1")
    p.add_argument("--max-iter", type=_options.positive_int, default=60,
                   help="iteration limit (default 60)")
    _options.add_accuracy_options(p, FIT_SETTINGS, max_steps=False)
    _options.add_cache_flag(p)
    p.add_argument("--quiet", action="store_true", help="no progress line on stderr")


def _spec_options(args, n_traces):
    """ModelSpec keyword arguments and shared names from the options (UsageError if bad)."""
    _options.check_substrate_options(args, layer_under_viscoelastic=False)
    if args.compare and args.substrate == "viscoelastic":
        raise UsageError("--compare fits the viscoelastic model itself: leave out --substrate "
                         "viscoelastic")
    shared = ()
    if args.shared is not None:
        shared = tuple(x.strip() for x in args.shared.split(",") if x.strip())
        bad = [x for x in shared if x not in SHAREABLE]
        if bad or not shared:
            raise UsageError(f"--shared: unknown parameter(s) {', '.join(bad) or repr(args.shared)}"
                             f" (allowed: {', '.join(SHAREABLE)})")
        if n_traces < 2:
            raise UsageError("--shared needs at least two traces (a joint fit)")
        if any(x in ("stiffening", "relaxation_time") for x in shared) and (
                args.substrate != "viscoelastic"):
            raise UsageError("--shared stiffening/relaxation_time need --substrate viscoelastic")
    layer = ((args.thickness, _options.layer_poisson(args), _options.layer_base(args))
             if args.thickness else None)
    return dict(layer=layer, viscoelastic=args.substrate == "viscoelastic",
                fit_offset=not args.no_offset, indenter=args.indenter), shared


def _fixed_option(args, spec: ModelSpec, shared) -> dict:
    """--fix NAME=VALUE[,NAME=VALUE] (repeatable) as {name: float}; UsageError if bad."""
    fixed = {}
    for item in ",".join(args.fix or []).split(","):
        if not item.strip():
            continue
        name, eq, value = item.partition("=")
        name = name.strip()
        if not eq:
            raise UsageError(f"--fix: write NAME=VALUE (e.g. viscosity=1e-3), got {item!r}")
        if name not in spec.names:
            raise UsageError(f"--fix: unknown parameter {name!r} for this model (allowed: "
                             f"{', '.join(spec.names)})")
        if name == "offset" and args.no_offset:
            raise UsageError("--fix offset: --no-offset already holds it at 0")
        if name in fixed:
            raise UsageError(f"--fix: {name} is given twice")
        if name in shared:
            raise UsageError(f"--fix {name}: it is also in --shared; fit it jointly or fix it")
        try:
            fixed[name] = float(value)
        except ValueError:
            raise UsageError(f"--fix {name}: {value.strip()!r} is not a number") from None
    return fixed


def _start_warnings(traces, scales, starts, fixed: dict) -> list[str]:
    """Implausible starting values (from the physics, before any fitting): a unit slip."""
    out = []
    for tr, sc, start in zip(traces, scales, starts, strict=True):
        values = {n: v for n, v in start.values.items() if n not in fixed}
        for flag in plausibility_flags(values, sc.speed, e_star_range(tr.metadata)):
            out.append(f"{os.path.basename(tr.name)}: before fitting, from the data: {flag}")
    return out


def _run(args) -> int:
    _files.check_distinct_inputs(args.traces, "trace")
    spec_kw, shared = _spec_options(args, len(args.traces))
    # Settings checks the range itself (a ValueError: one line, exit 2, before any fitting)
    accuracy = _options.accuracy_settings(args)
    settings = dataclasses.replace(FIT_SETTINGS, **accuracy) if accuracy else None
    plots = []
    if args.plot is not None:
        if not args.plot.strip():
            raise UsageError("--plot: empty file name")
        _files.plot_format(args.plot)  # before the per-trace names, so the message shows the user's
        plots = plot_paths(args.plot, args.traces)
    outputs = [("--out", args.out), ("--table", args.table), ("--report", args.report)] + [
        ("--plot", p) for p in plots]
    _files.check_outputs(outputs, inputs=args.traces, input_label="input trace")
    progress = _Progress(args.quiet)
    comparison = None
    read_kw = dict(force_sign=args.force_sign)
    if args.columns is not None:
        read_kw["columns"] = parse_columns(args.columns, "--columns")
    if args.units is not None:
        read_kw["units"] = parse_units(args.units, "--units")
    try:
        traces = _read_all(args, read_kw)
        if plots and len(plots) != len(traces):  # a force map: one plot per curve
            plots = plot_paths(args.plot, [_curve_label(tr.name) for tr in traces])
            outputs = [o for o in outputs if o[0] != "--plot"] + [("--plot", p) for p in plots]
            _files.check_outputs(outputs, inputs=args.traces, input_label="input trace")
        spec = ModelSpec(drive=_common_drive(traces, args.drive), **spec_kw)
        fixed = _fixed_option(args, spec, shared)
        # the fit starts from these (scales_from_trace also refuses a force negative in
        # compression, before any output is prepared)
        scales, starts = scales_and_starts(traces, spec)
        for line in _start_warnings(traces, scales, starts, fixed):
            sys.stderr.write(f"{PROG}: warning: {line}\n")
        _files.prepare_outputs(outputs)  # creates missing folders: only once the inputs are good
        cached = None
        if not args.no_cache:  # a repeated call loads the compiled solver instead of compiling
            cached = enable_compilation_cache()
        progress(f"read {len(traces)} trace(s); " + (
            "compiling the solver, or loading it from the cache ..."
            if cached else "compiling the solver ..."))
        kw = dict(shared=shared, method=args.method, max_iter=args.max_iter, noise=args.noise,
                  progress=progress, scales=scales, starts=starts)
        if fixed:
            kw["fixed"] = fixed
        if settings is not None:
            kw["settings"] = settings
        if args.compare:
            # A layer is compared with the default it would replace (the half-space); the
            # half-space with the viscoelastic solid.
            pair = (dict(simple=dataclasses.replace(spec, layer=None), rich=spec)
                    if spec.layer is not None else dict(simple=spec))
            simple, rich, comparison = compare_models(traces, **pair, **kw)
            use_rich = comparison["choice"] == comparison["rich"]
            results, other = (rich, simple) if use_rich else (simple, rich)
        else:
            results, other = fit_traces(traces, spec=spec, **kw), None
    finally:
        progress.clear()  # an error message or the summary follows
    _write_results(args, results, other, comparison, plots)
    return _files.EXIT_OK if all(r.converged for r in results) else _files.EXIT_FAILED


def _write_results(args, results, other, comparison, plots) -> None:
    """The summary lines on stdout, then every output asked for."""
    for res in results:
        print(summary_line(res))
        for flag in res.flags[1:]:
            print(f"  warning: {flag}")
    if comparison is not None:
        print("model comparison: " + comparison["report"][-1])
    dicts = [result_to_dict(r) for r in results]
    if other is not None:
        for d, o in zip(dicts, other):
            d["alternative"] = {k: v for k, v in result_to_dict(o).items()
                                if k not in ("comparison", "metadata")}
    if args.out:
        with _files.atomic_open(args.out, "w") as fh:
            json.dump(dicts[0] if len(dicts) == 1 else dicts, fh, indent=2)
        print(f"wrote {args.out}")
    if args.table:
        write_table(results, args.table)
        print(f"wrote {args.table}")
    if args.report:
        with _files.atomic_open(args.report, "w") as fh:
            fh.write("\n\n".join(fit_report(r) for r in results) + "\n")
        print(f"wrote {args.report}")
    for res, path in zip(results, plots):
        plot_fit(res, path)
        print(f"wrote {path}")


class _Progress:
    """The progress line on stderr: a terminal gets one line redrawn in place; a redirected log
    one plain line per message, with no control characters."""

    def __init__(self, quiet: bool):
        self.quiet, self.shown = quiet, False
        self.start, self.tty = time.perf_counter(), sys.stderr.isatty()

    def __call__(self, msg: str) -> None:
        if self.quiet:
            return
        line = f"[{time.perf_counter() - self.start:6.1f} s] {msg}"
        if self.tty:
            self.shown = True
            width = shutil.get_terminal_size().columns - 1
            sys.stderr.write("\r\033[K" + line[:width])
        else:
            sys.stderr.write(line + "\n")
        sys.stderr.flush()

    def clear(self) -> None:
        if self.shown:
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()


def _curve_label(name: str) -> str:
    """"map.jpk-force-map#3" -> "map_curve3.jpk-force-map" (plot_paths keeps the stem)."""
    path, sep, index = name.rpartition("#")
    if not sep:
        return name
    root, ext = os.path.splitext(path)
    return f"{root}_curve{index}{ext}"


def _read_all(args, read_kw):
    """Every trace of the inputs: vendor files through afmformats (a force map gives one per
    curve), delimited text through ``read_trace``."""
    afm_opts = dict(radius=args.radius, poisson=args.poisson, baseline=args.baseline,
                    max_samples=args.max_samples, curves=args.curve,
                    drive=args.drive if args.drive is not None else "spring",
                    indenter=args.indenter)
    try:
        afm_opts["segments"] = _afm.parse_segments(args.segments)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    traces, afm_used = [], False
    for path in args.traces:
        if _afm.is_afm_file(path):
            afm_used = True
            if afm_opts["drive"] not in _afm.DRIVES:
                raise UsageError(f"--drive {args.drive}: an AFM file is read for the drives "
                                 f"{', '.join(_afm.DRIVES)} (the cantilever is a spring)")
            traces.extend(_afm.read_afm(path, **afm_opts))
        else:
            traces.append(read_trace(path, **read_kw))
    if not afm_used:
        given = [f"--{k.replace('_', '-')}" for k in ("radius", "poisson", "curve")
                 if getattr(args, k) is not None]
        if given:
            raise UsageError(f"{', '.join(given)}: only for AFM vendor files")
    return traces


def _common_drive(traces, drive):
    try:
        return common_drive(traces, drive)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def main(argv=None) -> int:
    """Run ``lubjax-fit`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    return _files.run_cli(PROG, build_parser(), _run, argv)


if __name__ == "__main__":
    sys.exit(main())

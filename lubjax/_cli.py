"""``lubjax relax``: run a relaxation test from the command line (also ``python -m lubjax``).

Every failure is one line on stderr with exit status 2 (bad usage or input, found before any
computation) or 1 (the run failed, or an output could not be written); ``--debug`` shows the
traceback. Outputs are checked before the run and written atomically (see ``_files``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import shutil
import sys
import textwrap
import threading
import time

import numpy as np

from ._checks import travel_over_radius_problem
from ._cli_options import (
    POISSON_TEXT,
    accuracy_settings,
    add_accuracy_options,
    add_cache_flag,
    add_debug_flag,
    add_indenter_option,
    add_substrate_options,
    check_substrate_options,
    example_lines,
    layer_base,
    layer_poisson,
    option_name,
    positive_float,
)
from ._files import (
    EXIT_EPILOG,
    Parser,
    UsageError,
    atomic_open,
    check_outputs,
    prepare_outputs,
    read_load_csv,
    run_cli,
)

PROG = "lubjax"
DESCRIPTION = (
    "Simulate a soft lubricated contact with the lubjax solver: a rigid sphere pushed into a "
    "soft elastic half-space (or a layer, or a viscoelastic solid: --substrate) through a "
    "viscous film, then held (relax), pressed under a load (creep), or a free sphere colliding "
    "with it (bounce). "
    "Also available as: python -m lubjax"
)
EPILOG = EXIT_EPILOG.format(failed="solver error, or an output could not be written")
_MATERIAL = "--E-star 3.92e6 --viscosity 100 --radius 2e-3"
_BOUNCE = "--E-star 1e6 --viscosity 0.01 --radius 2e-3 --density 7800 --speed 0.05 --gap 50e-6"
_SI_RELAX = f"{_MATERIAL} --speed 1e-4 --indent 140e-6 --gap 140e-6"
_CREEP = f"{_MATERIAL} --load 0.03 --ramp-time 1 --hold 29 --gap 140e-6"
#: Runnable examples ending each command's --help (tests/test_cli_output.py runs them).
EXAMPLES = {
    "lubjax": [
        "lubjax relax --beta 100 --z0 0.5 --plot relax.png",
        f"lubjax creep {_CREEP} --plot creep.png",
        f"lubjax bounce {_BOUNCE} --plot bounce.png",
    ],
    "relax": [
        "lubjax relax --beta 100 --z0 0.5 --t-end 5 --out relax.json",
        f"lubjax relax {_SI_RELAX} --t-end 20 --plot relax.png",
        f"lubjax relax {_SI_RELAX} --substrate layer --thickness 5e-3 --plot layer.png",
    ],
    "creep": [
        f"lubjax creep {_CREEP} --plot creep.png",
        f"lubjax creep {_CREEP} --substrate viscoelastic --prony-g 0.5 --prony-tau 0.5 "
        "--out creep.json",
    ],
    "bounce": [
        f"lubjax bounce {_BOUNCE} --plot bounce.png",
        f"lubjax bounce {_BOUNCE} --substrate layer --thickness 1e-3 --out bounce.json",
    ],
}


def _epilog(command: str) -> str:
    """The exit statuses, then runnable examples (the last thing --help shows)."""
    examples = "\n".join(f"  {example_lines(line)}" for line in EXAMPLES[command])
    return f"{EPILOG}\n\nexamples:\n{examples}"


SI_NAMES = ("E_star", "E", "poisson", "viscosity", "radius", "speed", "indent", "gap")


#: A run shorter than this shows no progress line; the line is redrawn this often.
PROGRESS_AFTER_S = 2.0
PROGRESS_EVERY_S = 0.5
@contextlib.contextmanager
def progress_line(what: str, stream=None):
    """A line "[elapsed] what: phase ..." redrawn on ``stream`` (stderr) once the body has taken
    :data:`PROGRESS_AFTER_S`, only when ``stream`` is a terminal (a redirected log gets no
    control characters); cleared at the end. Yields the callable to pass as ``relax``'s
    ``progress``, which names the phase shown."""
    stream = sys.stderr if stream is None else stream
    phase = ["starting"]

    def tell(name: str) -> None:
        phase[0] = name

    isatty = getattr(stream, "isatty", None)
    if not (callable(isatty) and isatty()):
        yield tell
        return
    start, done = time.perf_counter(), threading.Event()
    shown = False

    def draw():
        nonlocal shown
        if done.wait(PROGRESS_AFTER_S):
            return
        while not done.is_set():
            line = f"[{time.perf_counter() - start:6.1f} s] {what}: {phase[0]} ..."
            width = shutil.get_terminal_size().columns - 1
            stream.write("\r\033[K" + line[:width])
            stream.flush()
            shown = True
            done.wait(PROGRESS_EVERY_S)

    ticker = threading.Thread(target=draw, daemon=True)
    ticker.start()
    try:
        yield tell
    finally:
        done.set()
        ticker.join()
        if shown:
            stream.write("\r\033[K")
            stream.flush()


def _parser() -> Parser:
    p = Parser(prog=PROG, description=DESCRIPTION, epilog=_epilog("lubjax"))
    add_debug_flag(p)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_relax_command, _add_creep_command, _add_bounce_command):
        command = add(sub)
        add_cache_flag(command)
        add_debug_flag(command)
    return p


def _add_relax_command(sub):
    r = sub.add_parser(
        "relax",
        help="simulate a ramp-and-hold relaxation test",
        description="Give either --beta and --z0 (dimensionless) or all the SI parameters: "
        "--E-star (or --E with --poisson), --viscosity, --radius, --speed, --indent, --gap.",
        epilog=_epilog("relax"),
    )
    r.add_argument("--beta", type=float, help="beta (paper eq 8e)")
    r.add_argument("--z0", type=float, help="dimensionless initial gap z0/d_c")
    r.add_argument(
        "--t-end",
        type=positive_float,
        default=None,
        help="end time: dimensionless (default 5), or in s in SI mode",
    )
    si = r.add_argument_group("SI mode")
    si.add_argument("--E-star", type=float, help="plane-strain modulus E* [Pa] (with --substrate "
                    "viscoelastic: the relaxed E*∞)")
    si.add_argument("--E", type=float, help="Young's modulus [Pa] (with --poisson)")
    si.add_argument("--poisson", type=float, help=f"Poisson's ratio in {POISSON_TEXT} (with --E)")
    si.add_argument("--viscosity", type=float, help="film viscosity [Pa s]")
    si.add_argument("--radius", type=float, help="sphere radius [m]")
    si.add_argument("--speed", type=float, help="approach speed v0 [m/s]")
    si.add_argument("--indent", type=float, help="travel d_c [m]")
    si.add_argument("--gap", type=float, help="initial gap z0 [m]")
    add_indenter_option(si)
    _add_substrate(r, dimensionless=True)
    r.add_argument(
        "--dr", type=positive_float, default=None, help="fine-zone mesh spacing (Settings.dr)"
    )
    _add_accuracy(r)
    return r


def _add_creep_command(sub):
    c = sub.add_parser(
        "creep",
        help="simulate a creep test: a load ramped and held (force control)",
        description="A load ramped from 0 to --load in --ramp-time, held for --hold (or the "
        "load history of --load-csv, columns time_s,force_N), on a sphere starting at rest at "
        "--gap. Dimensionless numbers use d_c = the Hertz indentation under the (peak) load "
        "and t_c = the ramp time (the time to the peak load for --load-csv).",
        epilog=_epilog("creep"),
    )
    _add_material(c)
    c.add_argument("--load", type=positive_float, help="load F [N] (ramp-and-hold)")
    c.add_argument("--ramp-time", type=positive_float, help="time to reach the load [s]")
    c.add_argument("--hold", type=float, default=None, help="hold time after the ramp [s]")
    c.add_argument("--load-csv", help="a load history instead: CSV with time_s,force_N")
    c.add_argument("--gap", type=float, help="initial gap z0 [m]")
    add_indenter_option(c)
    _add_substrate(c)
    _add_accuracy(c)
    return c


def _add_bounce_command(sub):
    b = sub.add_parser(
        "bounce",
        help="simulate a free sphere colliding with the substrate through the film",
        description="A sphere of --mass (or --density) approaching at --speed from the gap "
        "--gap (Davis, Serayssol & Hinch 1986), optionally under --weight. Dimensionless "
        "numbers use d_c = gap and t_c = gap/speed; the restitution coefficient is the speed "
        "when the sphere passes back through the starting gap, over the approach speed.",
        epilog=_epilog("bounce"),
    )
    _add_material(b)
    b.add_argument("--mass", type=positive_float, help="sphere mass [kg]")
    b.add_argument("--density", type=positive_float, help="sphere density [kg/m³] (or --mass)")
    b.add_argument("--speed", type=positive_float, help="approach speed V [m/s]")
    b.add_argument("--gap", type=float, help="initial gap [m]")
    b.add_argument("--weight", type=float, default=0.0,
                   help="constant force toward the wall [N] (weight less buoyancy; default 0)")
    b.add_argument("--t-end", type=positive_float, default=None,
                   help="end time [s] (default 20 --gap/--speed)")
    _add_substrate(b)
    _add_accuracy(b)
    return b


def _add_material(p):
    si = p.add_argument_group("material")
    si.add_argument("--E-star", type=float, help="plane-strain modulus E* [Pa] (with --substrate "
                    "viscoelastic: the relaxed E*∞)")
    si.add_argument("--E", type=float, help="Young's modulus [Pa] (with --poisson)")
    si.add_argument("--poisson", type=float, help=f"Poisson's ratio in {POISSON_TEXT} (with --E)")
    si.add_argument("--viscosity", type=float, help="film viscosity [Pa s]")
    si.add_argument("--radius", type=float, help="sphere radius [m]")


def _add_accuracy(p):
    """The solver's accuracy options and the outputs (every command)."""
    from ._solve import Settings

    add_accuracy_options(p, Settings())
    p.add_argument("--out", help="write results as JSON here")
    p.add_argument("--plot", help="write a figure here (.png, .pdf, .svg, ...)")


PRONY_OPTIONS = ("prony_g", "prony_tau")


def _add_substrate(p, dimensionless=False):
    """The substrate options, the same for every command (built by :func:`_substrate`)."""
    si_only = " (SI mode)" if dimensionless else ""
    tau_units = ("[s] in SI mode, in t_c units with --beta/--z0 (as --t-end)" if dimensionless
                 else "[s]")
    # the parser keeps descriptions as written (RawDescriptionHelpFormatter): wrap it here
    g = p.add_argument_group("substrate", textwrap.fill(
        f"A layer{si_only} on its base, or a viscoelastic solid given by its Prony series "
        "(--prony-g, --prony-tau; on the layer if --thickness is given). "
        "The solver scales with the relaxed modulus: for a viscoelastic substrate E* (--E-star, "
        "or --E with --poisson) is the relaxed E*∞, the long-time modulus, and the Prony series "
        "E(t)/E∞ = 1 + Σ g_k exp(-t/τ_k) gives the instantaneous E*0 = E*∞ (1 + Σ g_k).",
        76))
    add_substrate_options(g)
    g.add_argument("--prony-g", metavar="G1[,G2...]", default=None,
                   help="Prony modulus weights g_k = E_k/E∞ > 0 (dimensionless, relative to the "
                   "relaxed modulus; E0/E∞ = 1 + sum)")
    g.add_argument("--prony-tau", metavar="TAU1[,TAU2...]", default=None,
                   help=f"Prony relaxation times τ_k > 0, distinct, one per weight, {tau_units}")


def _prony_list(args, name, what):
    """The comma-separated numbers of --prony-g/--prony-tau, each finite and > 0."""
    text = getattr(args, name)
    values = []
    for k, cell in enumerate(text.split(","), 1):
        try:
            v = float(cell)
        except ValueError:
            raise UsageError(f"{option_name(name)}: term {k} is not a number: {cell.strip()!r} "
                             f"(give {what}, comma-separated)") from None
        if not (math.isfinite(v) and v > 0):
            raise UsageError(f"{option_name(name)}: term {k} must be a finite number > 0 ({what}), "
                             f"got {cell.strip()}")
        values.append(v)
    return values


def _substrate(args, settings, scale):
    """The substrate from the substrate options, as (substrate or None for the half-space, its
    JSON record, a line for the summary or None); every mistake a UsageError naming the option,
    before anything is computed. ``scale``: (R [m], d_c [m], t_c [s]) of the run, or None in
    dimensionless mode (lengths in metres are then refused; times are in t_c units)."""
    from ._layer import k_nodes, layer_thickness_bar
    from ._substrate import Layer, Viscoelastic

    kind = args.substrate
    check_substrate_options(args, layer_under_viscoelastic=True)
    prony_given = [option_name(n) for n in PRONY_OPTIONS if getattr(args, n) is not None]
    if kind != "viscoelastic" and prony_given:
        raise UsageError(f"{', '.join(prony_given)}: only with --substrate viscoelastic")
    if kind == "viscoelastic":
        missing = [option_name(n) for n in PRONY_OPTIONS if getattr(args, n) is None]
        if missing:
            raise UsageError("--substrate viscoelastic needs " + " and ".join(missing)
                             + " (--prony-g G1[,G2...] --prony-tau TAU1[,TAU2...])")

    layer, record, line = None, {"kind": "halfspace"}, None
    if args.thickness is not None:
        if scale is None:
            raise UsageError("--thickness is in metres: give the SI parameters (--E-star, "
                             "--viscosity, --radius, --speed, --indent, --gap), not --beta/--z0")
        radius, d_c, _ = scale
        layer = Layer(layer_thickness_bar(args.thickness, radius, d_c), layer_poisson(args),
                      layer_base(args))
        try:  # the matrix's cost depends on the mesh length only: refuse a too thin layer now
            k_nodes(settings.mesh(), layer.thickness, layer.poisson, layer.interface)
        except ValueError as exc:
            raise UsageError(f"--thickness {args.thickness:g} m: {exc}") from None
        record = {"kind": "layer", "thickness_m": args.thickness, "thickness_bar": layer.thickness,
                  "poisson": layer.poisson, "base": layer.interface}
        line = (f"{layer.interface} layer H = {args.thickness:g} m "
                f"(H/sqrt(R d_c) = {layer.thickness:.4g}), poisson {layer.poisson:g}")
    if kind != "viscoelastic":
        return layer, record, line

    g = _prony_list(args, "prony_g", "weights E_k/E∞")
    tau = _prony_list(args, "prony_tau", "times in s" if scale else "times in t_c units")
    if len(g) != len(tau):
        raise UsageError(f"--prony-g has {len(g)} term(s) and --prony-tau {len(tau)}: give one "
                         "relaxation time per weight")
    if len(set(tau)) != len(tau):
        raise UsageError("--prony-tau: the relaxation times must be distinct, got "
                         f"{args.prony_tau}")
    t_c = scale[2] if scale else 1.0
    tau_bar = [t / t_c for t in tau]
    try:
        solid = Viscoelastic.from_prony(g, tau_bar, elastic=layer)
    except ValueError as exc:  # the exact conversion to the compliance form failed
        raise UsageError(f"--prony-g/--prony-tau: {exc}") from None
    record = {
        "kind": "viscoelastic",
        "modulus": "E* is the relaxed modulus E*inf; E*0 = E*inf (1 + sum g)",
        "prony_g": g,
        "prony_tau_s": tau if scale else None,
        "prony_tau_bar": tau_bar,
        "E0_over_Einf": 1.0 + sum(g),
        "retardation": solid.retardation.tolist(),
        "retardation_times_bar": solid.times.tolist(),
        "elastic": record,
    }
    unit = "s" if scale else "t_c"
    line = (f"viscoelastic, {len(g)} Prony term(s), E*0/E*inf = {1 + sum(g):.4g}, tau = "
            + ", ".join(f"{t:.4g}" for t in tau) + f" {unit} (t_c units: "
            + ", ".join(f"{t:.4g}" for t in tau_bar) + "), on "
            + (line if line else "the half-space"))
    return solid, record, line


def _modulus(args) -> float:
    from ._units import plane_strain_modulus

    if args.E_star is not None and (args.E is not None or args.poisson is not None):
        raise UsageError("give either --E-star or --E with --poisson, not both")
    if args.E_star is None and (args.E is None or args.poisson is None):
        raise UsageError("give --E-star (or --E with --poisson)")
    return args.E_star if args.E_star is not None else plane_strain_modulus(args.E, args.poisson)


def _require(args, names):
    missing = [n for n in names if getattr(args, n.replace("-", "_")) is None]
    if missing:
        raise UsageError("this command needs --" + ", --".join(missing))


def _check_thin(name, value, radius, indenter="paraboloid"):
    problem = travel_over_radius_problem(name, value, radius, indenter)
    if problem:
        raise UsageError(problem)


def _check_thin_given(args, names):
    """:func:`_check_thin` of the options ``names`` (travels and gaps) in the options' own
    words, before the SI test class refuses them in its own; a value the class refuses for
    another reason (not positive, not finite) is left to it."""
    def usable(x):
        return x is not None and math.isfinite(x) and x > 0

    if usable(args.radius):
        for name in names:
            value = getattr(args, name)
            if usable(value):
                _check_thin(f"--{name}", value, args.radius, args.indenter)


def _check_end(t_end: float, given: str, time_scale: float | None = None, t_c: str = "",
               fix=None) -> float:
    """The end time t̄ (``t_end``, t_c units), refused beyond the solver's ``T_END_MAX`` in the
    user's own units: ``given`` is what they typed ("--t-end 1e+12 s"), ``time_scale`` t_c [s]
    in SI mode (None: dimensionless), ``t_c`` what t_c is, ``fix(limit_s)`` the fix in SI."""
    from ._checks import T_END_MAX

    if t_end <= T_END_MAX * (1 + 1e-12):  # the limit itself, as the user wrote it in seconds
        return min(t_end, T_END_MAX)
    if time_scale is None:
        raise UsageError(f"{given}: the solver runs to t̄ = {T_END_MAX:g} at most (in t_c "
                         f"units); give at most {T_END_MAX:g}")
    limit_s = T_END_MAX * time_scale
    raise UsageError(
        f"{given} is t̄ = {t_end:.4g} (t_c = {t_c} = {time_scale:.4g} s); the solver runs to "
        f"t̄ = {T_END_MAX:g} at most, {limit_s:.4g} s here: {fix(limit_s)}"
    )


def _at_most(x: float) -> str:
    """``x`` to 4 significant digits, rounded down (a limit to quote: never above it)."""
    y = float(f"{x:.4g}")
    if y > x * (1 + 1e-12):
        y -= 10.0 ** (math.floor(math.log10(x)) - 3)
    return f"{y:.4g}"


def _settings(args):
    from ._solve import Settings

    return Settings(**accuracy_settings(args))


def _result_json(res, test=None, z0_m=None):
    """The JSON every ``lubjax`` command writes: the dimensionless series with their error
    estimates and the run's cost; given ``test`` (its scales), the same in SI units; given
    ``z0_m`` (the starting gap [m] of a drive), the sphere's position and approach too."""
    out = {
        "beta": res.beta,
        "z0": res.z0,
        "t": res.t.tolist(),
        "force": res.force.tolist(),
        "h_min": res.film_min.tolist(),
        "h_center": res.film_center.tolist(),
        "force_error": res.force_error.tolist(),
        "h_min_error": res.film_min_error.tolist(),
        "h_center_error": res.film_center_error.tolist(),
        "steps": res.accepted,
        "rejected_steps": res.rejected,
        "run_s": res.run_s,
        "compile_s": res.compile_s,
        "ok": res.ok,
        "problems": res.problems(),  # the text relax's SolverError and Result.problems() give
        "unresolved_film": res.unresolved_film(),
    }
    if test is None:
        return out
    scales = test.scales
    d, f = scales["gap_m"], scales["force_N"]  # d_c, and the force scale
    out.update(
        t_s=(res.t * scales["time_s"]).tolist(),
        force_N=(res.force * f).tolist(),
        h_min_m=(res.film_min * d).tolist(),
        h_center_m=(res.film_center * d).tolist(),
        force_error_N=(res.force_error * f).tolist(),
        h_min_error_m=(res.film_min_error * d).tolist(),
        scales=scales,
    )
    if z0_m is not None:
        out.update(
            gap=res.gap.tolist(),
            gap_m=(res.gap * d).tolist(),
            approach_m=(z0_m - res.gap * d).tolist(),
            gap_error_m=(res.gap_error * d).tolist(),
        )
    return out


def _creep(args) -> int:
    from ._indenter import SampledTravel
    from ._solve import check_parameters, relax
    from ._units import CreepTest

    e_star = _modulus(args)
    _require(args, ["viscosity", "radius", "gap"])
    _check_thin_given(args, ("gap",))
    outputs = [("--out", args.out), ("--plot", args.plot)]
    check_outputs(outputs, inputs=[args.load_csv] if args.load_csv else ())
    history = None
    if args.load_csv:
        if args.load is not None or args.ramp_time is not None:
            raise UsageError("give either --load-csv or --load with --ramp-time, not both")
        ts, fs = read_load_csv(args.load_csv)
        peak = int(np.argmax(fs))
        load, ramp = float(fs[peak]), float(ts[peak] - ts[0])
        if ramp <= 0:
            raise UsageError(f"{args.load_csv}: the load must rise from its first row")
        test = CreepTest(e_star, args.radius, args.viscosity, load, ramp, args.gap,
                         args.indenter)
        history = SampledTravel((ts - ts[0]) / ramp, fs / load)
        t_end = _check_end((ts[-1] - ts[0]) / ramp, f"{args.load_csv}: the load history",
                           ramp, "the time to the peak load",
                           lambda limit: f"give a history at most {_at_most(limit)} s long")
    else:
        _require(args, ["load", "ramp-time", "hold"])
        if not (math.isfinite(args.hold) and args.hold >= 0):
            raise UsageError(f"--hold must be >= 0 s, got {args.hold}")
        test = CreepTest(e_star, args.radius, args.viscosity, args.load, args.ramp_time, args.gap,
                         args.indenter)
        ramp = args.ramp_time
        t_end = _check_end((ramp + args.hold) / ramp,
                           f"--ramp-time + --hold = {ramp + args.hold:g} s", ramp, "--ramp-time",
                           lambda limit: f"give --hold <= {_at_most(limit - ramp)} s")
    _check_thin("--gap", test.gap, test.radius, test.indenter)
    _check_thin("the Hertz indentation under the load", test.indent, test.radius, test.indenter)
    check_parameters(test.beta, test.z0_bar)
    settings = _settings(args)
    # d_c = the Hertz indentation at E* (the relaxed one if viscoelastic), t_c = the ramp time
    substrate, record, line = _substrate(args, settings,
                                         (test.radius, test.indent, test.time_scale))
    prepare_outputs(outputs)
    profile_times = sorted({min(1.0, t_end), t_end})
    if line:
        print(f"substrate: {line}")
    with progress_line("creep") as phase:
        res = relax(test.beta, test.z0_bar, t_end, drive=test.drive(history),
                    settings=settings, profile_times=profile_times, substrate=substrate,
                    progress=phase, indenter=test.shape)
    out = _result_json(res, test, z0_m=test.gap)
    out.update(load_N=test.load, hertz_indentation_m=test.indent,
               settings=dataclasses.asdict(settings), substrate=record)
    d = test.indent
    print(
        f"creep: beta={test.beta:.4g} z0={test.z0_bar:.4g} (d_c = Hertz indentation "
        f"{d:.4g} m, t_c = {test.time_scale:.4g} s): approach at the end "
        f"{test.gap - res.gap[-1] * d:.5g} m (Hertz: {test.gap + d:.5g} m), "
        f"film h(0) {res.film_center[-1] * d:.3g} m; {res.accepted} steps, run {res.run_s:.3f} s,"
        f" compile {res.compile_s:.2f} s"
    )
    _write(args, out, lambda path: _plot_drive(res, path, "creep", test, line))
    return 0


def _bounce(args) -> int:
    from ._drives import restitution
    from ._solve import check_parameters, relax
    from ._units import Collision

    e_star = _modulus(args)
    _require(args, ["viscosity", "radius", "speed", "gap"])
    if (args.mass is None) == (args.density is None):
        raise UsageError("give either --mass or --density")
    if not (math.isfinite(args.weight) and args.weight >= 0):
        raise UsageError(f"--weight must be >= 0 N, got {args.weight}")
    outputs = [("--out", args.out), ("--plot", args.plot)]
    check_outputs(outputs)
    mass = args.mass if args.mass else args.density * 4 / 3 * math.pi * args.radius**3
    test = Collision(e_star, args.radius, args.viscosity, mass, args.speed, args.gap, args.weight)
    _check_thin("--gap", test.gap, test.radius)
    check_parameters(test.beta, 1.0)
    t_end = 20.0 if args.t_end is None else _check_end(
        args.t_end / test.time_scale, f"--t-end {args.t_end:g} s", test.time_scale,
        "--gap/--speed", lambda limit: f"give --t-end <= {_at_most(limit)} s")
    settings = _settings(args)
    # d_c = the gap x0, t_c = x0/V
    substrate, record, line = _substrate(args, settings, (test.radius, test.gap, test.time_scale))
    prepare_outputs(outputs)
    if line:
        print(f"substrate: {line}")
    # Profiles at the end and at impact (the peak force): the impact is found by the run, so a
    # plot takes a second run for its profiles, with as many profile times (the same program)
    # and no error estimate (the steps, and so the series, are the same).
    with progress_line("bounce") as phase:
        res = relax(test.beta, 1.0, t_end, drive=test.drive(), settings=settings,
                    profile_times=[t_end, t_end], substrate=substrate, progress=phase)
        if args.plot:
            impact = float(res.t[np.argmax(res.force)])
            again = relax(test.beta, 1.0, t_end, drive=test.drive(),
                          settings=dataclasses.replace(settings, error_estimate=False),
                          profile_times=[impact, t_end], substrate=substrate,
                          progress=lambda p: phase(f"profiles at impact: {p}"))
            res = dataclasses.replace(res, profile_times=again.profile_times,
                                      pressure=again.pressure, displacement=again.displacement,
                                      film=again.film)
    e = restitution(res)
    out = _result_json(res, test, z0_m=test.gap)
    v = test.speed
    out.update(
        velocity=res.velocity.tolist(),
        velocity_m_s=(res.velocity * v).tolist(),
        restitution=None if math.isnan(e) else e,
        restitution_read_at="the starting gap (--gap), moving away",
        stokes=test.stokes,
        elasticity_davis=test.elasticity,
        mass_kg=mass,
        settings=dataclasses.asdict(settings),
        substrate=record,
    )
    print(bounce_summary(res, test, e))
    _write(args, out, lambda path: _plot_drive(res, path, "bounce", test, line,
                                               ["impact: peak force", "end"]))
    return 0


def bounce_summary(res, test, e) -> str:
    """The line ``lubjax bounce`` prints (SI). The sphere's position z is its rigid-body
    position above the undeformed surface: it goes below 0 when the film pressure indents the
    substrate, so the closest approach is told by the film, not by z."""
    x0, ts, fs = test.gap, test.time_scale, test.force_scale
    low, thin, peak = (int(np.argmin(res.gap)), int(np.argmin(res.film_min)),
                       int(np.argmax(res.force)))
    indent = (" (below the undeformed surface: the substrate is indented)"
              if res.gap[low] < 0 else "")
    return (
        f"bounce: St={test.stokes:.4g}, beta={test.beta:.4g} (Davis et al.'s epsilon "
        f"{test.elasticity:.3g}): peak film force {res.force[peak] * fs:.4g} N at t = "
        f"{res.t[peak] * ts:.4g} s; minimum film thickness {res.film_min[thin] * x0 * 1e6:.4g} um "
        f"at t = {res.t[thin] * ts:.4g} s; lowest sphere position (rigid body) z = "
        f"{res.gap[low] * x0 * 1e6:.4g} um at t = {res.t[low] * ts:.4g} s{indent}; restitution "
        + ("none (no rebound to the starting --gap)" if math.isnan(e) else f"{e:.4f}")
        + f"; {res.accepted} steps, run {res.run_s:.3f} s, compile {res.compile_s:.2f} s"
    )


def _write(args, out, plot):
    """The one writer of every ``lubjax`` command: the JSON ``out`` to --out (atomically), then
    ``plot(path)`` to --plot."""
    if args.out:
        with atomic_open(args.out, "w") as f:
            json.dump(out, f)
        print(f"wrote {args.out}")
    if args.plot:
        plot(args.plot)
        print(f"wrote {args.plot}")


def _plot_drive(res, path, kind, test, substrate, notes=None):
    from ._plotting import plot_drive

    plot_drive(res, path, kind, test, substrate=substrate, profile_notes=notes)


def _plot_relax(res, path, test, substrate):
    from ._plotting import plot_result

    plot_result(res, path, test=test, substrate=substrate)


def _dispatch(args) -> int:
    if not args.no_cache:  # a repeated call loads the compiled solver instead of compiling it
        from ._compile_cache import enable_compilation_cache

        enable_compilation_cache()
    return {"relax": _relax, "creep": _creep, "bounce": _bounce}[args.command](args)


def _si_test(args):
    from ._units import RelaxationTest

    if args.E_star is not None and (args.E is not None or args.poisson is not None):
        raise UsageError("give either --E-star or --E with --poisson, not both")
    names = ["viscosity", "radius", "speed", "indent", "gap"]
    missing = [n for n in names if getattr(args, n) is None]
    if args.E_star is None and (args.E is None or args.poisson is None):
        missing.append("E-star (or --E with --poisson)")
    if missing:
        raise UsageError("SI mode needs --" + ", --".join(missing))
    _check_thin_given(args, ("indent", "gap"))
    return RelaxationTest(_modulus(args), args.radius, args.viscosity, args.speed, args.indent,
                          args.gap, args.indenter)


def relax_summary(res, test=None) -> str:
    """The line ``lubjax relax`` prints: in SI units (s, N, μm) when ``test`` (the run's
    :class:`RelaxationTest`) is given, else dimensionless."""
    peak = int(np.argmax(res.force))
    cost = (f"{res.accepted} steps ({res.rejected} rejected), run {res.run_s:.3f} s, "
            f"compile {res.compile_s:.2f} s")
    err = np.nanmax(res.force_error)
    if test is None:
        return (f"beta={res.beta:.4g} z0={res.z0:.4g}: F(t_end)={res.force[-1]:.5g}, "
                f"peak F={res.force[peak]:.5g}, min film={res.film_min.min():.3g}; "
                f"estimated error {err:.2g}; {cost}")
    ts, fs, um = test.time_scale, test.force_scale, test.indent * 1e6
    thin = int(np.argmin(res.film_min))
    return (f"relax: beta={res.beta:.4g} z0/d_c={res.z0:.4g} (d_c = {test.indent:.4g} m, "
            f"t_c = {ts:.4g} s): force at t = {res.t[-1] * ts:.4g} s {res.force[-1] * fs:.5g} N, "
            f"peak {res.force[peak] * fs:.5g} N at t = {res.t[peak] * ts:.4g} s; thinnest film "
            f"{res.film_min[thin] * um:.3g} um at t = {res.t[thin] * ts:.4g} s; estimated force "
            f"error {err * fs:.2g} N; {cost}")


def _relax(args) -> int:
    from ._solve import Settings, check_parameters, relax

    si_given = any(getattr(args, n) is not None for n in SI_NAMES)
    if si_given and (args.beta is not None or args.z0 is not None):
        raise UsageError("give either --beta/--z0 or SI parameters, not both")
    if not si_given and (args.beta is None or args.z0 is None):
        raise UsageError("give --beta and --z0, or the SI parameters (see lubjax relax --help)")
    if not si_given and args.indenter == "sphere":
        raise UsageError("--indenter sphere needs the SI parameters: the sphere's profile "
                         "depends on d_c/R (--indent, --radius), which --beta/--z0 do not give")
    outputs = [("--out", args.out), ("--plot", args.plot)]
    check_outputs(outputs)
    test = _si_test(args) if si_given else None
    beta, z0 = (test.beta, test.z0_bar) if test else (args.beta, args.z0)
    check_parameters(beta, z0)  # the solver's valid ranges, before anything is compiled
    if args.t_end is None:
        t_end = 5.0
    elif test:
        t_end = _check_end(args.t_end / test.time_scale, f"--t-end {args.t_end:g} s",
                           test.time_scale, "--indent/--speed",
                           lambda limit: f"give --t-end <= {_at_most(limit)} s")
    else:
        t_end = _check_end(args.t_end, f"--t-end {args.t_end:g}")
    if not (math.isfinite(t_end) and t_end > 0):
        raise UsageError(f"--t-end must be > 0, got {args.t_end}")
    given = accuracy_settings(args) | ({"dr": args.dr} if args.dr is not None else {})
    settings = Settings(**given)
    scale = (test.radius, test.indent, test.time_scale) if test else None
    substrate, record, line = _substrate(args, settings, scale)
    profile_times = [t for t in (0.25, 0.5, 1.0, 2.0, t_end) if t <= t_end]
    prepare_outputs(outputs)
    with progress_line("relax") as phase:
        res = relax(beta, z0, t_end, settings=settings, profile_times=profile_times,
                    substrate=substrate, progress=phase, indenter=test.shape if test else None)
    out = _result_json(res, test)
    out.update(settings=dataclasses.asdict(settings), substrate=record)
    if line:
        print(f"substrate: {line}")
    print(relax_summary(res, test))
    note = res.unresolved_film()
    if note:
        if test:
            note += (f" (t̄ = t/t_c, t_c = {test.time_scale:.4g} s; h̄ = h/d_c, "
                     f"d_c = {test.indent:.4g} m)")
        print(f"note: {note}")
    _write(args, out, lambda path: _plot_relax(res, path, test, line))
    return 0


def main(argv=None) -> int:
    """Run ``lubjax`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    return run_cli(PROG, _parser(), _dispatch, argv)


if __name__ == "__main__":
    sys.exit(main())

"""The ``lubjax`` commands' arguments as scenes (SI set-up, checks) and the one run-and-write."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from ._checks import T_END_MAX, check_parameters, travel_over_radius_problem
from ._cli_options import (
    accuracy_settings,
    check_substrate_options,
    layer_base,
    layer_poisson,
    option_name,
)
from ._cli_output import (
    bounce_summary,
    creep_summary,
    plot_drive,
    plot_relax,
    progress_line,
    relax_summary,
    result_json,
    write_outputs,
)
from ._drives import restitution
from ._files import UsageError, check_outputs, prepare_outputs, read_load_csv
from ._indenter import SampledTravel
from ._layer import k_nodes, layer_thickness_bar
from ._settings import Settings
from ._substrate import Layer, Viscoelastic
from ._units import Collision, CreepTest, RelaxationTest, plane_strain_modulus

SI_NAMES = ("E_star", "E", "poisson", "viscosity", "radius", "speed", "indent", "gap")
PRONY_OPTIONS = ("prony_g", "prony_tau")


@dataclasses.dataclass(frozen=True)
class Scene:
    """One command's run, its arguments checked and converted: what :func:`lubjax.relax` is
    given, and how the command reports the result (:func:`run_scene`).

    Attributes:
        command: "relax", "creep" or "bounce" (the progress line's name).
        beta: β of the run.
        z0: z̄0 of the run.
        t_end: t̄_end of the run.
        settings: the run's Settings.
        profile_times: the profile times t̄.
        substrate: the substrate (None: the half-space).
        substrate_record: the JSON's ``substrate``.
        substrate_line: what the command prints about the substrate (None: nothing).
        summary: ``res`` -> the lines printed after the run.
        plot: ``(res, path)`` -> the figure.
        drive: the drive (None: relax's ramp-and-hold travel).
        indenter: the indenter's profile (None: the paraboloid).
        test: the SI test whose scales the JSON adds (None: a dimensionless run).
        start_gap_m: the starting gap [m] of a drive, for the sphere's position in the JSON.
        json_extra: ``res`` -> the command's own JSON entries.
        second_run: None, or ``(scene, res, phase)`` -> ``res`` with the profiles of a second
            run at times the first one found.
    """

    command: str
    beta: float
    z0: float
    t_end: float
    settings: Settings
    profile_times: list
    substrate: object
    substrate_record: dict
    substrate_line: str | None
    summary: Callable
    plot: Callable
    drive: object = None
    indenter: object = None
    test: object = None
    start_gap_m: float | None = None
    json_extra: Callable = lambda res: {}
    second_run: Callable | None = None


def outputs_of(args) -> list:
    """The output options of every command, as (option, path)."""
    return [("--out", args.out), ("--plot", args.plot)]


def run_scene(args, scene: Scene) -> int:
    """Run ``scene`` and write what every command writes: the substrate's line, the progress
    line while it runs, the summary, the JSON to --out and the figure to --plot (the outputs
    were checked by the scene's set-up, before anything ran)."""
    from ._solve import relax  # looked up at each run: the tests stand a fake in for it

    prepare_outputs(outputs_of(args))
    if scene.substrate_line:
        print(f"substrate: {scene.substrate_line}")
    with progress_line(scene.command) as phase:
        res = relax(scene.beta, scene.z0, scene.t_end, drive=scene.drive,
                    settings=scene.settings, profile_times=scene.profile_times,
                    substrate=scene.substrate, progress=phase, indenter=scene.indenter)
        if scene.second_run is not None:
            res = scene.second_run(scene, res, phase)
    out = result_json(res, scene.test, z0_m=scene.start_gap_m)
    out.update(scene.json_extra(res), settings=dataclasses.asdict(scene.settings),
               substrate=scene.substrate_record)
    for line in scene.summary(res):
        print(line)
    write_outputs(args, out, lambda path: scene.plot(res, path))
    return 0


def relax_scene(args) -> Scene:
    """``lubjax relax``: dimensionless (--beta, --z0) or in SI units."""
    si_given = any(getattr(args, n) is not None for n in SI_NAMES)
    if si_given and (args.beta is not None or args.z0 is not None):
        raise UsageError("give either --beta/--z0 or SI parameters, not both")
    if not si_given and (args.beta is None or args.z0 is None):
        raise UsageError("give --beta and --z0, or the SI parameters (see lubjax relax --help)")
    if not si_given and args.indenter == "sphere":
        raise UsageError("--indenter sphere needs the SI parameters: the sphere's profile "
                         "depends on d_c/R (--indent, --radius), which --beta/--z0 do not give")
    check_outputs(outputs_of(args))
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
    settings = settings_of(args)
    scale = (test.radius, test.indent, test.time_scale) if test else None
    substrate, record, line = substrate_of(args, settings, scale)
    return Scene(
        "relax", beta, z0, t_end, settings,
        [t for t in (0.25, 0.5, 1.0, 2.0, t_end) if t <= t_end], substrate, record, line,
        summary=lambda res: _relax_lines(res, test),
        plot=lambda res, path: plot_relax(res, path, test, line),
        test=test, indenter=test.shape if test else None,
    )


def _relax_lines(res, test):
    """What ``lubjax relax`` prints after its run: the summary and a note on the film."""
    lines = [relax_summary(res, test)]
    note = res.unresolved_film()
    if note:
        if test:
            note += (f" (t̄ = t/t_c, t_c = {test.time_scale:.4g} s; h̄ = h/d_c, "
                     f"d_c = {test.indent:.4g} m)")
        lines.append(f"note: {note}")
    return lines


def creep_scene(args) -> Scene:
    """``lubjax creep``: a load ramped and held, or a measured load history (--load-csv)."""
    e_star = _modulus(args)
    _require(args, ["viscosity", "radius", "gap"])
    _check_thin_given(args, ("gap",))
    check_outputs(outputs_of(args), inputs=[args.load_csv] if args.load_csv else ())
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
    _check_thin("the Hertz indentation under the load", test.indent, test.radius, test.indenter)
    check_parameters(test.beta, test.z0_bar)
    settings = settings_of(args)
    # d_c = the Hertz indentation at E* (the relaxed one if viscoelastic), t_c = the ramp time
    substrate, record, line = substrate_of(args, settings,
                                           (test.radius, test.indent, test.time_scale))
    return Scene(
        "creep", test.beta, test.z0_bar, t_end, settings, sorted({min(1.0, t_end), t_end}),
        substrate, record, line,
        summary=lambda res: [creep_summary(res, test)],
        plot=lambda res, path: plot_drive(res, path, "creep", test, line),
        drive=test.drive(history), indenter=test.shape, test=test, start_gap_m=test.gap,
        json_extra=lambda res: {"load_N": test.load, "hertz_indentation_m": test.indent},
    )


def bounce_scene(args) -> Scene:
    """``lubjax bounce``: a free sphere colliding with the substrate through the film."""
    e_star = _modulus(args)
    _require(args, ["viscosity", "radius", "speed", "gap"])
    if (args.mass is None) == (args.density is None):
        raise UsageError("give either --mass or --density")
    if not (math.isfinite(args.weight) and args.weight >= 0):
        raise UsageError(f"--weight must be >= 0 N, got {args.weight}")
    check_outputs(outputs_of(args))
    mass = args.mass if args.mass else args.density * 4 / 3 * math.pi * args.radius**3
    test = Collision(e_star, args.radius, args.viscosity, mass, args.speed, args.gap, args.weight)
    _check_thin("--gap", test.gap, test.radius)
    check_parameters(test.beta, 1.0)
    t_end = 20.0 if args.t_end is None else _check_end(
        args.t_end / test.time_scale, f"--t-end {args.t_end:g} s", test.time_scale,
        "--gap/--speed", lambda limit: f"give --t-end <= {_at_most(limit)} s")
    settings = settings_of(args)
    # d_c = the gap x0, t_c = x0/V
    substrate, record, line = substrate_of(args, settings, (test.radius, test.gap, test.time_scale))

    def json_extra(res):
        e = restitution(res)
        v = test.speed
        return dict(
            velocity=res.velocity.tolist(),
            velocity_m_s=(res.velocity * v).tolist(),
            restitution=None if math.isnan(e) else e,
            restitution_read_at="the starting gap (--gap), moving away",
            stokes=test.stokes,
            elasticity_davis=test.elasticity,
            mass_kg=mass,
        )

    return Scene(
        "bounce", test.beta, 1.0, t_end, settings, [t_end, t_end], substrate, record, line,
        summary=lambda res: [bounce_summary(res, test, restitution(res))],
        plot=lambda res, path: plot_drive(res, path, "bounce", test, line,
                                          ["impact: peak force", "end"]),
        drive=test.drive(), test=test, start_gap_m=test.gap, json_extra=json_extra,
        second_run=_profiles_at_impact if args.plot else None,
    )


def _profiles_at_impact(scene, res, phase):
    """``res`` with its profiles at impact (the peak force) and at the end. The impact is found
    by the run, so a plot takes a second run for its profiles, with as many profile times (the
    same program) and no error estimate (the steps, and so the series, are the same)."""
    from ._solve import relax

    impact = float(res.t[np.argmax(res.force)])
    again = relax(scene.beta, scene.z0, scene.t_end, drive=scene.drive,
                  settings=dataclasses.replace(scene.settings, error_estimate=False),
                  profile_times=[impact, scene.t_end], substrate=scene.substrate,
                  progress=lambda p: phase(f"profiles at impact: {p}"))
    return dataclasses.replace(res, profile_times=again.profile_times, pressure=again.pressure,
                               displacement=again.displacement, film=again.film)


#: Each command's set-up, by name.
SCENES = {"relax": relax_scene, "creep": creep_scene, "bounce": bounce_scene}


def settings_of(args) -> Settings:
    """The run's Settings: the library's, with the accuracy options given (and relax's --dr)."""
    dr = getattr(args, "dr", None)
    return Settings(**accuracy_settings(args) | ({"dr": dr} if dr is not None else {}))


def _si_test(args):
    """``lubjax relax``'s SI parameters as a :class:`lubjax.RelaxationTest`."""
    modulus_given = _modulus_given(args)
    names = ["viscosity", "radius", "speed", "indent", "gap"]
    missing = [n for n in names if getattr(args, n) is None]
    if not modulus_given:
        missing.append("E-star (or --E with --poisson)")
    if missing:
        raise UsageError("SI mode needs --" + ", --".join(missing))
    _check_thin_given(args, ("indent", "gap"))
    return RelaxationTest(_modulus(args), args.radius, args.viscosity, args.speed, args.indent,
                          args.gap, args.indenter)


def _modulus_given(args) -> bool:
    """Whether E* is given, by --E-star or by --E with --poisson; UsageError for both."""
    if args.E_star is not None and (args.E is not None or args.poisson is not None):
        raise UsageError("give either --E-star or --E with --poisson, not both")
    return args.E_star is not None or (args.E is not None and args.poisson is not None)


def _modulus(args) -> float:
    """E* [Pa] from --E-star, or from --E with --poisson; UsageError for both or neither."""
    if not _modulus_given(args):
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


def substrate_of(args, settings, scale):
    """The substrate from the substrate options, as (substrate or None for the half-space, its
    JSON record, a line for the summary or None); every mistake a UsageError naming the option,
    before anything is computed. ``scale``: (R [m], d_c [m], t_c [s]) of the run, or None in
    dimensionless mode (lengths in metres are then refused; times are in t_c units)."""
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

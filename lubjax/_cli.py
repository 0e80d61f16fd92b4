"""``lubjax relax``: run a relaxation test from the command line (also ``python -m lubjax``).

Every failure is one line on stderr with exit status 2 (bad usage or input, found before any
computation) or 1 (the run failed, or an output could not be written); ``--debug`` shows the
traceback. Outputs are checked before the run and written atomically (see ``_files``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys

import numpy as np

from ._files import (
    EXIT_EPILOG,
    MAX_TRAVEL_OVER_RADIUS,
    Parser,
    UsageError,
    add_debug_flag,
    atomic_open,
    check_outputs,
    positive_float,
    prepare_outputs,
    run_cli,
)

PROG = "lubjax"
DESCRIPTION = (
    "Simulate a soft lubricated contact with the lubjax solver: a rigid sphere pushed into a "
    "soft elastic half-space through a viscous film, then held (a relaxation test). "
    "Also available as: python -m lubjax"
)
EPILOG = EXIT_EPILOG.format(failed="solver error, or an output could not be written")
SI_NAMES = ("E_star", "E", "poisson", "viscosity", "radius", "speed", "indent", "gap")


def _parser() -> Parser:
    p = Parser(prog=PROG, description=DESCRIPTION, epilog=EPILOG)
    add_debug_flag(p)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    r = sub.add_parser(
        "relax",
        help="simulate a ramp-and-hold relaxation test",
        description="Give either --beta and --z0 (dimensionless) or all the SI parameters: "
        "--E-star (or --E with --poisson), --viscosity, --radius, --speed, --indent, --gap.",
        epilog=EPILOG,
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
    si.add_argument("--E-star", type=float, help="plane-strain modulus E* [Pa]")
    si.add_argument("--E", type=float, help="Young's modulus [Pa] (with --poisson)")
    si.add_argument("--poisson", type=float, help="Poisson's ratio in (-1, 0.5] (with --E)")
    si.add_argument("--viscosity", type=float, help="film viscosity [Pa s]")
    si.add_argument("--radius", type=float, help="sphere radius [m]")
    si.add_argument("--speed", type=float, help="approach speed v0 [m/s]")
    si.add_argument("--indent", type=float, help="travel d_c [m]")
    si.add_argument("--gap", type=float, help="initial gap z0 [m]")
    r.add_argument(
        "--dr", type=positive_float, default=None, help="fine-zone mesh spacing (Settings.dr)"
    )
    r.add_argument(
        "--rtol", type=positive_float, default=None,
        help="accuracy: local error tolerance of each step, and the mesh (Settings.rtol, "
        "default 3e-4)",
    )
    r.add_argument(
        "--max-steps", type=int, default=None, help="attempted-step budget (Settings.max_steps)"
    )
    r.add_argument("--order", type=int, choices=(1, 2), default=None, help="1: backward Euler")
    r.add_argument("--out", help="write results as JSON here")
    r.add_argument("--plot", help="write a force / film figure here (.png, .pdf, .svg, ...)")
    add_debug_flag(r)
    return p


def _si_test(args):
    from ._units import RelaxationTest, plane_strain_modulus

    if args.E_star is not None and (args.E is not None or args.poisson is not None):
        raise UsageError("give either --E-star or --E with --poisson, not both")
    names = ["viscosity", "radius", "speed", "indent", "gap"]
    missing = [n for n in names if getattr(args, n) is None]
    if args.E_star is None and (args.E is None or args.poisson is None):
        missing.append("E-star (or --E with --poisson)")
    if missing:
        raise UsageError("SI mode needs --" + ", --".join(missing))
    e_star = args.E_star if args.E_star is not None else plane_strain_modulus(args.E, args.poisson)
    test = RelaxationTest(e_star, args.radius, args.viscosity, args.speed, args.indent, args.gap)
    for name, value in [("--indent", test.indent), ("--gap", test.gap)]:
        if value > MAX_TRAVEL_OVER_RADIUS * test.radius:
            raise UsageError(
                f"{name} {value:g} m is {value / test.radius:.3g} radii (--radius {test.radius:g} "
                f"m); the thin-film model needs it ≪ R (at most {MAX_TRAVEL_OVER_RADIUS:g} R). "
                "Are the lengths in metres?"
            )
    return test


def _relax(args) -> int:
    from ._solve import Settings, check_parameters, relax

    si_given = any(getattr(args, n) is not None for n in SI_NAMES)
    if si_given and (args.beta is not None or args.z0 is not None):
        raise UsageError("give either --beta/--z0 or SI parameters, not both")
    if not si_given and (args.beta is None or args.z0 is None):
        raise UsageError("give --beta and --z0, or the SI parameters (see lubjax relax --help)")
    outputs = [("--out", args.out), ("--plot", args.plot)]
    check_outputs(outputs)
    test = _si_test(args) if si_given else None
    beta, z0 = (test.beta, test.z0_bar) if test else (args.beta, args.z0)
    check_parameters(beta, z0)  # the solver's valid ranges, before anything is compiled
    if args.t_end is None:
        t_end = 5.0
    else:
        t_end = args.t_end / test.time_scale if test else args.t_end
    if not (math.isfinite(t_end) and t_end > 0):
        raise UsageError(f"--t-end must be > 0, got {args.t_end}")
    given = [("dr", args.dr), ("rtol", args.rtol), ("order", args.order),
             ("max_steps", args.max_steps)]
    settings = Settings(**{k: v for k, v in given if v is not None})
    profile_times = [t for t in (0.25, 0.5, 1.0, 2.0, t_end) if t <= t_end]
    prepare_outputs(outputs)
    res = relax(beta, z0, t_end, settings=settings, profile_times=profile_times)
    out = {
        "beta": beta,
        "z0": z0,
        "t": res.t.tolist(),
        "force": res.force.tolist(),
        "h_min": res.film_min.tolist(),
        "h_center": res.film_center.tolist(),
        "run_s": res.run_s,
        "compile_s": res.compile_s,
        "force_error": res.force_error.tolist(),
        "steps": res.accepted,
        "rejected_steps": res.rejected,
        "ok": res.ok,
        "settings": dataclasses.asdict(settings),
    }
    if test:
        out.update(
            t_s=(res.t * test.time_scale).tolist(),
            force_N=(res.force * test.force_scale).tolist(),
            h_min_m=(res.film_min * test.indent).tolist(),
            scales={
                "time_s": test.time_scale,
                "force_N": test.force_scale,
                "length_m": test.length_scale,
                "pressure_Pa": test.pressure_scale,
            },
        )
    print(
        f"beta={beta:.4g} z0={z0:.4g}: F(t_end)={res.force[-1]:.5g}, peak F={res.force.max():.5g}, "
        f"min film={res.film_min.min():.3g}; estimated error {np.nanmax(res.force_error):.2g}; "
        f"{res.accepted} steps ({res.rejected} rejected), run {res.run_s:.3f} s, "
        f"compile {res.compile_s:.2f} s"
    )
    if args.out:
        with atomic_open(args.out, "w") as f:
            json.dump(out, f)
        print(f"wrote {args.out}")
    if args.plot:
        from ._plotting import plot_result

        plot_result(res, args.plot, test=test)
        print(f"wrote {args.plot}")
    return 0


def main(argv=None) -> int:
    """Run ``lubjax`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    return run_cli(PROG, _parser(), _relax, argv)


if __name__ == "__main__":
    sys.exit(main())

"""The ``lubjax`` command line: its parser and ``main`` (also ``python -m lubjax``).

Each command's arguments become a scene and one helper runs and writes it
(:mod:`lubjax._cli_scenes`); what the commands print and write is :mod:`lubjax._cli_output`.
Every failure is one line on stderr with exit status 2 (bad usage or input, found before any
computation) or 1 (the run failed, or an output could not be written); ``--debug`` shows the
traceback. Outputs are checked before the run and written atomically (see ``_files``).
"""

from __future__ import annotations

import sys
import textwrap

from ._cli_options import (
    POISSON_TEXT,
    add_accuracy_options,
    add_cache_flag,
    add_debug_flag,
    add_indenter_option,
    add_substrate_options,
    example_lines,
    positive_float,
)
from ._cli_scenes import SCENES, run_scene
from ._files import EXIT_EPILOG, Parser, run_cli
from ._settings import Settings

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
    add_accuracy_options(p, Settings())
    p.add_argument("--out", help="write results as JSON here")
    p.add_argument("--plot", help="write a figure here (.png, .pdf, .svg, ...)")



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


def _dispatch(args) -> int:
    if not args.no_cache:  # a repeated call loads the compiled solver instead of compiling it
        from ._compile_cache import enable_compilation_cache

        enable_compilation_cache()
    return run_scene(args, SCENES[args.command](args))


def main(argv=None) -> int:
    """Run ``lubjax`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    return run_cli(PROG, _parser(), _dispatch, argv)


if __name__ == "__main__":
    sys.exit(main())

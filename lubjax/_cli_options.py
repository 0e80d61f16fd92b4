"""The options ``lubjax`` and ``lubjax-fit`` share: each defined once here (name, type, default,
help), with the checks of the substrate options both need.

* :func:`add_substrate_options`, :func:`add_indenter_option`, :func:`add_accuracy_options`,
  :func:`add_cache_flag`,
  :func:`add_debug_flag`: the shared option groups; :func:`check_substrate_options`,
  :func:`layer_base` and :func:`layer_poisson` turn the substrate options into a choice, with
  every mistake a :class:`~lubjax._files.UsageError` naming the option.
* :func:`positive_float`, :func:`positive_int`: argparse types; :func:`example_lines`: the
  runnable examples that end each ``--help``.

``fitting`` (the ``lubjax-fit`` command line) may import this module; safe file writing and the
one-line errors (:class:`~lubjax._files.Parser`, :func:`~lubjax._files.run_cli`, the output
checks) are in :mod:`lubjax._files`.

The layer's defaults mean the same in both commands: ``--layer-base`` bonded, and
``--layer-poisson`` the solid's ``--poisson`` when given, else 0.5 (incompressible).
"""

from __future__ import annotations

import argparse
import math

from ._checks import (
    FILM_ERRORS,
    INDENTERS,
    LAYER_BASES,
    MAX_SPHERE_TRAVEL_OVER_RADIUS,
    MAX_TRAVEL_OVER_RADIUS,
    POISSON_RANGE,
    check_poisson,
)
from ._files import UsageError

#: Poisson's range as the help and messages write it.
POISSON_TEXT = f"({POISSON_RANGE[0]:g}, {POISSON_RANGE[1]:g}]"

SUBSTRATES = ("halfspace", "layer", "viscoelastic")
LAYER_OPTIONS = ("thickness", "layer_base", "layer_poisson")
#: What the layer options mean when not given (see :func:`layer_base`, :func:`layer_poisson`).
DEFAULT_LAYER_BASE = "bonded"
DEFAULT_LAYER_POISSON = 0.5
ORDERS = {1: "backward Euler", 2: "BDF2", 3: "BDF3"}


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer ≥ 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer ≥ 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer ≥ 1, got {text!r}")
    return value


def option_name(dest: str) -> str:
    """``"layer_base"`` -> ``"--layer-base"``."""
    return "--" + dest.replace("_", "-")


def example_lines(command: str, width: int = 76) -> str:
    """``command`` as shell lines of at most ``width`` columns (where an option and its value
    fit), continued with backslashes, never splitting an option from its value."""
    groups = []
    for word in command.split():
        if word.startswith("--") or not groups:
            groups.append(word)
        else:
            groups[-1] += " " + word
    lines = [groups[0]]
    for group in groups[1:]:
        if len(lines[-1]) + 1 + len(group) + 2 > width - 6:
            lines.append(group)
        else:
            lines[-1] += " " + group
    return " \\\n      ".join(lines)


# --------------------------------------------------------------------------- option groups


def add_substrate_options(group) -> None:
    """--substrate, --thickness, --layer-base, --layer-poisson on ``group`` (a parser or an
    argument group, whose description says what the command does with a viscoelastic solid)."""
    group.add_argument("--substrate", choices=SUBSTRATES, default="halfspace",
                       help="elastic half-space (default), a layer of thickness --thickness on a "
                       "rigid base, or a viscoelastic solid")
    group.add_argument("--thickness", type=positive_float, default=None,
                       help="layer thickness H [m]")
    group.add_argument("--layer-base", choices=LAYER_BASES, default=None,
                       help=f"layer on its rigid base: {DEFAULT_LAYER_BASE} (default) or "
                       "frictionless")
    group.add_argument("--layer-poisson", type=float, default=None,
                       help=f"Poisson ratio of the layer in {POISSON_TEXT} (default: --poisson if "
                       f"given, else {DEFAULT_LAYER_POISSON:g})")


def add_indenter_option(group) -> None:
    """--indenter: the paraboloid (default) or the sphere's true profile (lubjax/_shape.py)."""
    group.add_argument("--indenter", choices=INDENTERS, default="paraboloid",
                       help="the indenter's profile: paraboloid r²/2R (default; travel and gap at "
                       f"most {MAX_TRAVEL_OVER_RADIUS:g} R) or sphere, its true profile for deep "
                       f"indentation (Sneddon's contact; at most {MAX_SPHERE_TRAVEL_OVER_RADIUS:g} "
                       "R)")


def add_accuracy_options(parser, defaults, max_steps: bool = True) -> None:
    """--rtol, --order, --film-error (and --max-steps) of the solver; ``defaults``: the command's
    :class:`~lubjax.Settings`, whose values the options replace (None: not given)."""
    parser.add_argument("--rtol", type=positive_float, default=None,
                        help="accuracy: local error tolerance of each step, and the mesh "
                        f"(Settings.rtol; default {defaults.rtol:g}); tighter is slower")
    orders = ", ".join(f"{k}: {name}" + (" (default)" if k == defaults.order else "")
                       for k, name in ORDERS.items())
    parser.add_argument("--order", type=int, choices=tuple(ORDERS), default=None,
                        help=f"time integrator (Settings.order): {orders}; 3 takes fewer steps "
                        "at a tight --rtol")
    parser.add_argument(
        "--film-error", choices=FILM_ERRORS, default=None,
        help="what the film's error is held to (Settings.film_error; default "
        f"{defaults.film_error}): auto (relative below beta = 1e5, force from there on), "
        "relative (every film to rtol of itself) or force (inside a contact, through the force "
        "it moves: 2-8x fewer steps near dry; thin films less accurate)")
    if max_steps:
        parser.add_argument("--max-steps", type=positive_int, default=None,
                            help="attempted-step budget (Settings.max_steps; default "
                            f"{defaults.max_steps})")


def add_cache_flag(parser) -> None:
    parser.add_argument(
        "--no-cache", action="store_true",
        help="do not use the persistent compilation cache (also LUBJAX_CACHE=0; where it is: "
        "$LUBJAX_CACHE_DIR, else ~/.cache/lubjax/jax)",
    )


def add_debug_flag(parser) -> None:
    parser.add_argument(
        "--debug",
        action="store_true",
        default=argparse.SUPPRESS,
        help="on an error, show the Python traceback instead of the one-line message",
    )


def accuracy_settings(args) -> dict:
    """The accuracy options given, as Settings fields (the others keep the command's)."""
    given = {k: getattr(args, k, None) for k in ("rtol", "order", "max_steps", "film_error")}
    return {k: v for k, v in given.items() if v is not None}


# --------------------------------------------------------------------------- substrate checks


def check_substrate_options(args, layer_under_viscoelastic: bool) -> None:
    """The layer options only with a layer, a layer with its --thickness: UsageError naming the
    option. ``layer_under_viscoelastic``: whether the command takes a viscoelastic solid on a
    layer (``lubjax``; ``lubjax-fit`` fits a viscoelastic half-space only)."""
    kind = args.substrate
    given = [option_name(n) for n in LAYER_OPTIONS if getattr(args, n) is not None]
    allowed = ("layer", "viscoelastic") if layer_under_viscoelastic else ("layer",)
    if given and kind not in allowed:
        where = " (or viscoelastic on a layer)" if layer_under_viscoelastic else ""
        raise UsageError(f"{', '.join(given)}: only with --substrate layer{where}")
    if kind == "layer" and args.thickness is None:
        raise UsageError("--substrate layer needs --thickness H (metres)")
    if kind == "viscoelastic" and given and args.thickness is None:
        raise UsageError(f"{', '.join(given)}: with --substrate viscoelastic only together with "
                         "--thickness (the layer under the viscoelastic solid)")


def layer_base(args) -> str:
    """--layer-base, else :data:`DEFAULT_LAYER_BASE`."""
    return args.layer_base if args.layer_base is not None else DEFAULT_LAYER_BASE


def layer_poisson(args) -> float:
    """--layer-poisson, else the solid's --poisson when given, else
    :data:`DEFAULT_LAYER_POISSON`; UsageError outside (-1, 0.5]."""
    nu = args.layer_poisson
    if nu is None:
        poisson = getattr(args, "poisson", None)
        nu = poisson if poisson is not None else DEFAULT_LAYER_POISSON
    try:
        check_poisson("--layer-poisson", nu)
    except ValueError:
        raise UsageError(f"--layer-poisson must be in {POISSON_TEXT}, got {nu:g}") from None
    return nu

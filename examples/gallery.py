"""Regenerate the figures of the documentation's gallery (docs/gallery.md) with coarse settings.

    python examples/gallery.py [--out docs/figures/gallery] [--only relax,fit]

Each figure is made by the command line or example script that docs/gallery.md shows next to it,
run in this process (one import of jax, one compilation cache) with the arguments below, so
the page's commands and the committed PNGs stay the same. Settings are coarse (rtol 1e-3,
small grids): the figures show what each tool draws, not converged results.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time

import matplotlib

matplotlib.use("Agg")
from PIL import Image  # noqa: E402  (matplotlib's own dependency)

from fitting._cli import main as fit_main  # noqa: E402
from lubjax._cli import main as lubjax_main  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import paper_figures  # noqa: E402
import regime_map  # noqa: E402

OUT = "docs/figures/gallery"
_MATERIAL = "--E-star 3.92e6 --viscosity 100 --radius 2e-3"
_BOUNCE = "--E-star 1e6 --viscosity 0.01 --radius 2e-3 --density 7800 --speed 0.05 --gap 50e-6"

#: (name, command with {out} for the output folder): the commands docs/gallery.md shows.
FIGURES = (
    ("relax", "lubjax relax --beta 100 --z0 0.5 --rtol 1e-3 --plot {out}/relax.png"),
    ("relax_si", f"lubjax relax {_MATERIAL} --speed 1e-4 --indent 140e-6 --gap 140e-6 "
                 "--t-end 20 --rtol 1e-3 --plot {out}/relax_si.png"),
    ("creep", f"lubjax creep {_MATERIAL} --load 0.03 --ramp-time 1 --hold 29 --gap 140e-6 "
              "--rtol 1e-3 --plot {out}/creep.png"),
    ("bounce", f"lubjax bounce {_BOUNCE} --rtol 1e-3 --plot {{out}}/bounce.png"),
    ("fit", "lubjax-fit data/paper_dc140.csv --rtol 1e-3 --plot {out}/fit.png"),
    ("compare", "lubjax-fit data/visco_dc140.csv --compare --rtol 1e-3 --plot {out}/compare.png"),
    ("paper", "python examples/paper_figures.py --rtol 1e-3 --no-fig3 --dpi 100 --out {out}"),
    ("regime_map", "python examples/regime_map.py --n 10 --t-hold 20 --rtol 1e-3 --dpi 100 "
                   "--out {out}/regime_map.png"),
)

_RUNNERS = {
    "lubjax": lubjax_main,
    "lubjax-fit": fit_main,
    "examples/paper_figures.py": paper_figures.main,
    "examples/regime_map.py": regime_map.main,
}


def _outputs(command: str, out: str) -> set[str]:
    """The names of the files in ``out`` that a command writes (regenerated ones included)."""
    names = {os.path.basename(w) for w in shlex.split(command) if w.startswith(out + "/")}
    if "paper_figures.py" in command:
        names |= {"fig4_pressure.png", "fig5_film.png", "fig6_displacement.png"}
    return names


def run(command: str) -> None:
    """Run one gallery command (``lubjax ...``, ``lubjax-fit ...`` or ``python examples/...``)
    in this process; a nonzero exit status is an error."""
    words = shlex.split(command)
    if words[0] == "python":
        words = words[1:]
    status = _RUNNERS[words[0]](words[1:])
    if status not in (None, 0):
        raise SystemExit(f"gallery: {command!r} exited with status {status}")


def shrink(path: str) -> None:
    """Rewrite a PNG with a 256-colour palette: the same pixels to the eye (line plots and text)
    at a third to a half of the bytes, so the committed figures stay small."""
    with Image.open(path) as im:
        small = im.convert("RGB").quantize(colors=256)
    small.save(path, optimize=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=OUT, help=f"output folder (default {OUT})")
    ap.add_argument("--only", default=None,
                    help="comma-separated names to make: " + ", ".join(n for n, _ in FIGURES))
    args = ap.parse_args(argv)
    names = [n for n, _ in FIGURES]
    only = names if args.only is None else args.only.split(",")
    unknown = sorted(set(only) - set(names))
    if unknown:
        ap.error(f"--only: unknown figure(s) {', '.join(unknown)} (allowed: {', '.join(names)})")
    os.makedirs(args.out, exist_ok=True)
    for name, command in FIGURES:
        if name not in only:
            continue
        command = command.format(out=args.out)
        print(f"gallery: {command}", file=sys.stderr, flush=True)
        start = time.perf_counter()
        before = set(os.listdir(args.out))
        run(command)
        for fname in sorted(set(os.listdir(args.out)) - before | _outputs(command, args.out)):
            if fname.endswith(".png"):
                shrink(os.path.join(args.out, fname))
        print(f"gallery: {name} took {time.perf_counter() - start:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()

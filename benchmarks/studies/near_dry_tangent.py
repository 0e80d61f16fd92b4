"""Near dry in a long hold: what keeps relax's derivative right, the film held tighter or the
finer contact mesh, over the rounding of z̄0.

    python -m benchmarks.studies.near_dry_tangent [--quick]

At β = 10⁹ the force in the hold is Hertz's of the indentation, so dF̄/dz̄0 is Hertz's,
-π √(1 - z̄0). A differentiated run holds the near-dry film to ``TANGENT_FILM_CAP`` (100) rtol
of itself instead of ``FILM_CAP`` (10³) (``Tolerance.for_tangents``) and runs on a contact
mesh ``DRY_DERIVATIVE_REFINEMENT`` (1.4) times finer (``mesh_for(derivatives=True)``). Each
column sets those two constants:

* plain: cap 10³, the plain mesh (a differentiated run before either);
* cap: cap 100, the plain mesh;
* mesh: cap 10³, the finer mesh;
* both: cap 100, the finer mesh (the default).

Each cell: ``jax.jacfwd`` of relax's F̄ in z̄0 at HOLD_TIMES (t̄ ∈ [1.5, 10]), default
settings, no error estimate, the largest |slope/Hertz's - 1| ("NaN" where the tangent is).
z̄0 = 0.0997, 0.1003 and 0.1007 are 0.1 moved by less than a fit would notice: the rows show
how much the result hangs on rounding. ``--quick``: z̄0 = 0.1 and 0.0997 at β = 10⁹ only.
Writes benchmarks/out/near_dry_tangent.md. About 10 minutes on one core.
"""

from __future__ import annotations

from unittest import mock

import jax
import jax.numpy as jnp
import numpy as np

import lubjax
from benchmarks import _harness
from lubjax import _controller, _mesh

HOLD_TIMES = np.linspace(1.5, 10.0, 20)
T_END = 10.0
# (film cap, mesh refinement) of each column: "both" is what relax does
_PLAIN_CAP, _CAP = _controller.FILM_CAP, _controller.TANGENT_FILM_CAP
_FINER = _mesh.DRY_DERIVATIVE_REFINEMENT
VARIANTS = {"plain": (_PLAIN_CAP, 1.0), "cap": (_CAP, 1.0), "mesh": (_PLAIN_CAP, _FINER),
            "both": (_CAP, _FINER)}
CELLS = [(1e9, z0) for z0 in (0.05, 0.0997, 0.1, 0.1003, 0.1007, 0.5)] + [
    (1e8, z0) for z0 in (0.0997, 0.1)]
QUICK_CELLS = [(1e9, 0.1), (1e9, 0.0997)]


def hertz_error(beta, z0, cap, refinement):
    """The largest |dF̄/dz̄0 / Hertz's - 1| in the hold, with the two constants set."""
    settings = lubjax.Settings(error_estimate=False)
    with (mock.patch.object(_controller, "TANGENT_FILM_CAP", cap),
          mock.patch.object(_mesh, "DRY_DERIVATIVE_REFINEMENT", refinement)):
        jax.clear_caches()  # the cap is a constant of the compiled program
        slope = np.asarray(jax.jacfwd(lambda z: lubjax.relax(
            beta, z, T_END, settings=settings).at(HOLD_TIMES))(jnp.asarray(z0)))
    jax.clear_caches()
    if not np.all(np.isfinite(slope)):
        return float("nan")
    return float(np.max(np.abs(slope / (-np.pi * np.sqrt(1.0 - z0)) - 1.0)))


def main(argv=None):
    ap = _harness.parser(__doc__, "near_dry_tangent.md", quick="z̄0 = 0.1 and 0.0997 at β = 1e9")
    args = _harness.parse(ap, argv)
    cells = QUICK_CELLS if args.quick else CELLS
    lines = [
        "# Near dry: relax's dF̄/dz̄0 in a long hold against Hertz's", "",
        f"`{_harness.command(argv)}` ({_harness.label()}). t̄ ≤ {T_END:g}, default settings, "
        "the largest |slope/Hertz's − 1| over t̄ ∈ [1.5, 10]; columns: the film cap of a "
        "differentiated run and its contact mesh (module docstring).", "",
        "| β | z̄0 | " + " | ".join(VARIANTS) + " |",
        "|---|---|" + "---|" * len(VARIANTS),
    ]
    for beta, z0 in cells:
        errors = [hertz_error(beta, z0, *variant) for variant in VARIANTS.values()]
        lines.append(f"| {beta:g} | {z0:g} | "
                     + " | ".join("NaN" if np.isnan(e) else f"{e:.1e}" for e in errors) + " |")
        print(lines[-1], flush=True)
    _harness.write_report(args.out, lines)


if __name__ == "__main__":
    main()

"""Near dry, the contact's edge: how the refinement of the near-dry mesh's edge sets the force's
derivative in the indentation, at the default tolerance on the mesh of a differentiated relax run.

    python -m benchmarks.studies.near_dry_edge [--factors 3 6 12] [--quick]

Near dry the force is Hertz's, F̄_H = (2π/3) δ̄^{3/2}, whose derivative in the indentation is
π ā (ā = √δ̄ the contact's radius). A sharp near-dry edge between two nodes misplaces ā by a
fraction of a cell: an error of first order in the edge's spacing in dF̄/dz̄0, where the force's
own error is second order. Each row takes ``lubjax._mesh.DRY_RIM_REFINEMENT`` (the edge's
refinement, the default's 6) at each factor:

* half-space travel at β = 10⁷, z̄0 ∈ {0.5, 0.1, 0.05}, t̄ ≤ 5: ``jax.jacfwd`` of relax's F̄ in
  z̄0 at HOLD_TIMES against Hertz's, -π √(1 - z̄0) (the film's shift of the force is ~10⁻⁵ of
  it there), max relative error; and the force against Hertz's, max relative error;
* the viscoelastic solid (standard linear solid, E₀/E∞ = 3, τ = 0.5) at β = 10⁷, z̄0 = 0.5,
  t̄ ≤ 5, whose force relaxes in the hold: jacfwd against jacfwd of a run at rtol 10⁻⁶ on a
  finer mesh (Δr̄ = 0.007, the default edge), max over VE_TIMES relative to the
  largest |derivative|; that reference checked against central differences (steps 10⁻³ and
  2·10⁻³) of such runs wherever those are known to 10⁻⁴ (not at touchdown, t̄ ≈ z̄0, where
  the force's δ̄^{3/2} bends too sharply for a difference quotient).

``--quick``: z̄0 = 0.5 only, no viscoelastic row. Writes
benchmarks/out/near_dry_edge.md. About 3 minutes on one core.
"""

from __future__ import annotations

from unittest import mock

import jax
import jax.numpy as jnp
import numpy as np

import lubjax
from benchmarks import _harness
from lubjax import _mesh

BETA = 1e7
HOLD_TIMES = np.linspace(1.5, 5.0, 15)
VE_TIMES = np.linspace(0.5, 5.0, 10)
VISCOELASTIC = lubjax.Viscoelastic.standard_linear_solid(3.0, 0.5)
REFERENCE = lubjax.Settings(rtol=1e-6, dr=0.007, max_steps=200_000, error_estimate=False)
CD_STEP = 1e-3


def _with_edge(factor):
    """A context with the near-dry edge refined ``factor`` times."""
    return mock.patch.object(_mesh, "DRY_RIM_REFINEMENT", float(factor))


def _edge_run(factor, z0, times, substrate=None):
    """relax's F̄ at ``times`` and its dF̄/dz̄0 (one forward-mode run), at the default settings
    with the near-dry edge refined ``factor`` times; and the mesh's node count."""
    settings = lubjax.Settings(error_estimate=False)

    def force(z):
        return lubjax.relax(BETA, z, 5.0, substrate=substrate, settings=settings).at(times)

    with _with_edge(factor):
        values, slope = jax.jvp(force, (jnp.asarray(z0),), (jnp.ones(()),))
        # (the mesh of a differentiated run, as relax under jvp builds it)
        mesh = lubjax.mesh_for(settings, drive=lubjax.Travel(), beta=BETA, z0=z0, t_end=5.0,
                               derivatives=True)
    return np.asarray(values), np.asarray(slope), mesh.size


def travel_row(z0, factor):
    """(nodes, dF̄/dz̄0's error against Hertz's, the force's error against Hertz's)."""
    force, slope, size = _edge_run(factor, z0, HOLD_TIMES)
    hertz_slope = -np.pi * np.sqrt(1.0 - z0)
    force_error = np.max(np.abs(force / lubjax.hertz_force(z0) - 1.0))
    return size, np.max(np.abs(slope / hertz_slope - 1.0)), force_error


def viscoelastic_reference(z0=0.5):
    """jacfwd of the fine, tight run: dF̄/dz̄0 at VE_TIMES; and its largest difference from
    central differences (step CD_STEP) over the times where those are known to 10⁻⁴ (their
    steps h and 2h agree), relative to its largest, with how many times that leaves out."""
    def force(z):
        return lubjax.relax(BETA, z, 5.0, substrate=VISCOELASTIC, settings=REFERENCE).at(VE_TIMES)

    slope = np.asarray(jax.jacfwd(force)(jnp.asarray(z0)))
    scale = np.max(np.abs(slope))
    central = [(np.asarray(force(z0 + h)) - np.asarray(force(z0 - h))) / (2 * h)
               for h in (CD_STEP, 2 * CD_STEP)]
    known = np.abs(central[0] - central[1]) <= 1e-4 * scale
    check = np.max(np.abs(central[0] - slope)[known]) / scale
    return slope, check, int(np.sum(~known))


def viscoelastic_row(factor, reference, z0=0.5):
    """(nodes, dF̄/dz̄0's error against ``reference``, relative to its largest)."""
    _, slope, size = _edge_run(factor, z0, VE_TIMES, VISCOELASTIC)
    return size, np.max(np.abs(slope - reference)) / np.max(np.abs(reference))


def main(argv=None):
    ap = _harness.parser(__doc__, "near_dry_edge.md", quick="z̄0 = 0.5, no viscoelastic row")
    ap.add_argument("--factors", type=float, nargs="+", default=[3.0, 6.0, 12.0],
                    help="the edge's refinement factors (default 3 6 12; the default mesh: 6)")
    args = _harness.parse(ap, argv)
    lines = [
        "# Near dry, the contact's edge", "",
        f"`{_harness.command(argv)}` ({_harness.label()}). β = {BETA:g}, t̄ ≤ 5, a "
        "differentiated relax run's mesh at the default tolerance with the near-dry edge "
        "refined by each factor (nodes in brackets). Travel: dF̄/dz̄0 at t̄ = 1.5–5 against "
        "Hertz's, -π √(1 - z̄0), and the force against Hertz's, max relative errors. "
        "Viscoelastic solid (E₀/E∞ = 3, τ = 0.5): dF̄/dz̄0 at t̄ = 0.5–5 against that of an "
        "rtol 1e-6 run on a finer mesh (Δr̄ = 0.007), relative to the largest.", "",
        "| scene | " + " | ".join(f"edge ×{f:g}" for f in args.factors) + " |",
        "|---|" + "---|" * len(args.factors),
    ]
    for z0 in (0.5,) if args.quick else (0.5, 0.1, 0.05):
        cells, worst_force = [], 0.0
        for factor in args.factors:
            size, slope_error, force_error = travel_row(z0, factor)
            worst_force = max(worst_force, force_error)
            cells.append(f"{slope_error:.1e} ({size})")
            print(f"travel z̄0 = {z0:g}, edge ×{factor:g}: N = {size}, dF̄/dz̄0 {slope_error:.1e}, "
                  f"F̄ {force_error:.1e} off Hertz's", flush=True)
        lines.append(f"| travel, z̄0 = {z0:g} (F̄ ≤ {worst_force:.1e} off Hertz's) | "
                     + " | ".join(cells) + " |")
    if not args.quick:
        reference, check, left_out = viscoelastic_reference()
        print(f"viscoelastic reference: central differences agree with it to {check:.1e}, "
              f"{left_out} time(s) left out where they are not known to 1e-4", flush=True)
        cells = []
        for factor in args.factors:
            size, error = viscoelastic_row(factor, reference)
            cells.append(f"{error:.1e} ({size})")
            print(f"viscoelastic, edge ×{factor:g}: N = {size}, dF̄/dz̄0 {error:.1e}", flush=True)
        lines.append("| viscoelastic, z̄0 = 0.5 | " + " | ".join(cells) + " |")
        lines += ["", f"The viscoelastic reference agrees with central differences (steps "
                  f"{CD_STEP:g} and {2 * CD_STEP:g}) to {check:.1e} at the "
                  f"{VE_TIMES.size - left_out} of {VE_TIMES.size} times where those two steps "
                  "agree to 1e-4; where they do not (at touchdown, t̄ ≈ z̄0, the force's "
                  "δ̄^{3/2} bends too sharply for a difference quotient) it is the reference."]
    _harness.write_report(args.out, lines)


if __name__ == "__main__":
    main()

"""``lubjax relax``: run a relaxation test from the command line (also ``python -m lubjax``)."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lubjax", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser(
        "relax",
        help="simulate a ramp-and-hold relaxation test",
        description="Give either --beta and --z0 (dimensionless) or all the SI parameters.",
    )
    r.add_argument("--beta", type=float, help="β (eq 8e)")
    r.add_argument("--z0", type=float, help="z̄0 = z0/d_c")
    r.add_argument(
        "--t-end", type=float, default=None, help="end time: t̄ (default 5), or s in SI mode"
    )
    si = r.add_argument_group("SI mode")
    si.add_argument("--E-star", type=float, help="plane-strain modulus E* [Pa]")
    si.add_argument("--E", type=float, help="Young's modulus [Pa] (with --poisson)")
    si.add_argument("--poisson", type=float, help="Poisson's ratio (with --E)")
    si.add_argument("--viscosity", type=float, help="film viscosity [Pa s]")
    si.add_argument("--radius", type=float, help="sphere radius [m]")
    si.add_argument("--speed", type=float, help="approach speed v0 [m/s]")
    si.add_argument("--indent", type=float, help="travel d_c [m]")
    si.add_argument("--gap", type=float, help="initial gap z0 [m]")
    r.add_argument("--dr", type=float, default=None, help="fine-zone mesh spacing (Settings.dr)")
    r.add_argument("--dt", type=float, default=None, help="loading-phase step (Settings.dt)")
    r.add_argument("--order", type=int, choices=(1, 2), default=None, help="1: backward Euler")
    r.add_argument("--out", help="write results as JSON here")
    r.add_argument("--plot", help="write a force / film figure (PNG) here")
    return p


def _si_test(args):
    from ._units import RelaxationTest, plane_strain_modulus

    names = ["viscosity", "radius", "speed", "indent", "gap"]
    missing = [n for n in names if getattr(args, n) is None]
    if args.E_star is None and (args.E is None or args.poisson is None):
        missing.append("E-star (or E and poisson)")
    if missing:
        raise SystemExit("lubjax relax: SI mode needs --" + ", --".join(missing))
    e_star = args.E_star if args.E_star is not None else plane_strain_modulus(args.E, args.poisson)
    return RelaxationTest(e_star, args.radius, args.viscosity, args.speed, args.indent, args.gap)


def _relax(args) -> int:
    from ._solve import Settings, SolverError, relax

    si_given = any(
        getattr(args, n) is not None
        for n in ["E_star", "E", "viscosity", "radius", "speed", "indent", "gap"]
    )
    if si_given and (args.beta is not None or args.z0 is not None):
        raise SystemExit("lubjax relax: give either --beta/--z0 or SI parameters, not both")
    try:
        test = _si_test(args) if si_given else None
    except ValueError as err:
        print(f"lubjax relax: {err}", file=sys.stderr)
        return 2
    if test is None and (args.beta is None or args.z0 is None):
        raise SystemExit("lubjax relax: give --beta and --z0, or the SI parameters (see --help)")
    beta, z0 = (test.beta, test.z0_bar) if test else (args.beta, args.z0)
    if args.t_end is None:
        t_end = 5.0
    else:
        t_end = args.t_end / test.time_scale if test else args.t_end
    if not (math.isfinite(t_end) and t_end > 0):
        raise SystemExit(f"lubjax relax: --t-end must be > 0, got {args.t_end}")
    overrides = {k: v for k, v in [("dr", args.dr), ("dt", args.dt), ("order", args.order)] if v}
    try:
        settings = Settings(**overrides)
        profile_times = [t for t in (0.25, 0.5, 1.0, 2.0, t_end) if t <= t_end]
        res = relax(beta, z0, t_end, settings=settings, profile_times=profile_times)
    except (ValueError, SolverError) as err:
        print(f"lubjax relax: {err}", file=sys.stderr)
        return 2
    out = {
        "beta": beta,
        "z0": z0,
        "t": res.t.tolist(),
        "force": res.force.tolist(),
        "h_min": res.film_min.tolist(),
        "h_center": res.film_center.tolist(),
        "run_s": res.run_s,
        "compile_s": res.compile_s,
        "ok": res.ok,
        "settings": vars(settings) if hasattr(settings, "__dict__") else None,
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
        f"min film={res.film_min.min():.3g}; {res.t.size - 1} steps, "
        f"run {res.run_s:.3f} s, compile {res.compile_s:.2f} s"
    )
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, "w") as f:
            json.dump(out, f)
    if args.plot:
        from ._plotting import plot_result

        plot_result(res, args.plot, test=test)
    return 0


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "relax":
        return _relax(args)
    return 1


if __name__ == "__main__":
    sys.exit(main())

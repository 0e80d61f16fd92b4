"""What the ``lubjax`` commands write: summary lines, JSON, figures and the progress line."""

from __future__ import annotations

import contextlib
import json
import math
import shutil
import sys
import threading
import time

import numpy as np

from ._files import atomic_open

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


def result_json(res, test=None, z0_m=None):
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


def creep_summary(res, test) -> str:
    """The line ``lubjax creep`` prints (SI): the approach and the film at the end."""
    d = test.indent
    dry = "Sneddon" if test.indenter == "sphere" else "Hertz"
    return (
        f"creep: beta={test.beta:.4g} z0={test.z0_bar:.4g} (d_c = Hertz indentation "
        f"{d:.4g} m, t_c = {test.time_scale:.4g} s): approach at the end "
        f"{test.gap - res.gap[-1] * d:.5g} m ({dry}: {test.gap + test.dry_depth:.5g} m), "
        f"film h(0) {res.film_center[-1] * d:.3g} m; {res.accepted} steps, run {res.run_s:.3f} s,"
        f" compile {res.compile_s:.2f} s"
    )


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


def write_outputs(args, out, plot):
    """The one writer of every ``lubjax`` command: the JSON ``out`` to --out (atomically), then
    ``plot(path)`` to --plot."""
    if args.out:
        with atomic_open(args.out, "w") as f:
            json.dump(out, f)
        print(f"wrote {args.out}")
    if args.plot:
        plot(args.plot)
        print(f"wrote {args.plot}")


def plot_drive(res, path, kind, test, substrate, notes=None):
    """The figure of ``lubjax creep`` or ``bounce`` (``kind``), in SI units."""
    from ._plotting import plot_drive as plot

    plot(res, path, kind, test, substrate=substrate, profile_notes=notes)


def plot_relax(res, path, test, substrate):
    """The figure of ``lubjax relax``: in SI units given ``test``, else dimensionless."""
    from ._plotting import plot_result

    plot_result(res, path, test=test, substrate=substrate)

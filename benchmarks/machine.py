"""Benchmark outputs: the machine they ran on (CPU model, core count, load, threads used), and
writing a Markdown report."""

from __future__ import annotations

import os
import platform
import statistics


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def describe() -> dict:
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    return dict(
        cpu=cpu_model(),
        cores=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        threads=os.environ.get("OPENBLAS_NUM_THREADS", "?"),
        load1=round(load, 2),
    )


def label(info: dict | None = None) -> str:
    info = info or describe()
    return (f"{info['cpu']}, {info['cores']} cores, {info['threads']} thread(s) used, "
            f"load avg {info['load1']}")


def write_report(path: str, lines: list[str]) -> None:
    """Write ``lines`` as the Markdown report ``path`` (its folder made if missing) and print
    them."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def median_range(values) -> str:
    """``median (min–max)`` of repeated timings, two decimals."""
    values = list(values)
    return f"{statistics.median(values):.2f} ({min(values):.2f}–{max(values):.2f})"

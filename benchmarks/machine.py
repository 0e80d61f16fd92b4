"""Benchmark outputs: the code and machine they ran on (commit, CPU model, core count, load,
threads used), and writing a Markdown report."""

from __future__ import annotations

import os
import platform
import statistics
import subprocess


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def commit() -> str:
    """The checkout's commit (short hash), "+changes" when the tracked files differ from it;
    "unknown commit" outside a git checkout."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        head = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown commit"
    return f"commit {head}" + (" +changes" if dirty else "")


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
        commit=commit(),
    )


def label(info: dict | None = None) -> str:
    info = info or describe()
    return (f"{info.get('commit', commit())}, {info['cpu']}, {info['cores']} cores, "
            f"{info['threads']} thread(s) used, load avg {info['load1']}")


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

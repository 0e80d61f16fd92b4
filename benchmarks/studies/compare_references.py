"""The accuracy table's converged references against those of an earlier revision.

    python -m benchmarks.compare_references [--rev c01ce10]

benchmarks/accuracy.py caches its reference runs (``out/cache/ref_*.npz``, committed). When the
discretisation changes, the references are recomputed; the earlier ones stay in git. Reading both
at the table's output times, this prints per case max |ΔF̄|/peak, the pointwise |ΔF̄/F̄| where
F̄ > 1e-6 of the peak, and the largest relative changes of h̄(0) and h̄_min: two converged runs
of two discretisations (c01ce10: plain hat functions, outer growth 1.02; since: the
squeeze-film-weighted pressure, growth 1.05) that should agree to the references' own accuracy.
"""

from __future__ import annotations

import argparse
import io
import os
import re
import subprocess

import numpy as np

from benchmarks import accuracy
from benchmarks._harness import ROOT

CACHE = "benchmarks/out/cache"


def _earlier(rev: str) -> dict:
    """{(β, z̄0): arrays} of the ref_*.npz files committed at ``rev``."""
    names = subprocess.run(["git", "ls-tree", "--name-only", f"{rev}:{CACHE}"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    out = {}
    for name in names:
        m = re.fullmatch(r"ref_b([0-9.e+]+)_z([0-9.]+)_\w+\.npz", name)
        if not m:
            continue
        blob = subprocess.run(["git", "show", f"{rev}:{CACHE}/{name}"], cwd=ROOT,
                              capture_output=True, check=True).stdout
        out[(float(m.group(1)), float(m.group(2)))] = dict(np.load(io.BytesIO(blob)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rev", default="c01ce10", help="the revision whose references to read")
    args = ap.parse_args(argv)
    earlier = _earlier(args.rev)
    print(f"| β | z̄0 | F̄/peak | F̄ pointwise | h̄(0) | h̄_min |  (now vs {args.rev})")
    print("|---|---|---|---|---|---|")
    worst = np.zeros(4)
    for beta in accuracy.BETAS:
        for z0 in accuracy.Z0S:
            if (beta, z0) not in earlier or not os.path.exists(
                    accuracy.cache_path(beta, z0, "ref")):
                print(f"| {beta:g} | {z0:g} | missing | | | |")
                continue
            now = accuracy.reference(beta, z0, accuracy.REFERENCE, "ref")
            old = earlier[(beta, z0)]
            peak = np.max(now["force"])
            big = now["force"] > 1e-6 * peak
            row = np.array([
                np.max(np.abs(old["force"] - now["force"])) / peak,
                np.max(np.abs(old["force"][big] / now["force"][big] - 1)),
                np.max(np.abs(old["film_center"] / now["film_center"] - 1)),
                np.max(np.abs(old["film_min"] / now["film_min"] - 1)),
            ])
            worst = np.maximum(worst, row)
            print(f"| {beta:g} | {z0:g} | " + " | ".join(f"{x:.1e}" for x in row) + " |")
    print("| largest | | " + " | ".join(f"{x:.1e}" for x in worst) + " |")


if __name__ == "__main__":
    main()

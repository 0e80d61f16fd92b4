"""What the tests share: the data paths, the coarse settings, the scenes, the accuracy reference.

Coarse settings make runs cheap where a test checks a property of the scheme (an identity, an
order, a gradient), not the defaults' accuracy: one mesh of 0.05 spacing in the fine zone.
"""

import hashlib
import os
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from pathlib import Path

import numpy as np

import fitting
import lubjax
from fitting._scales import cut_trace

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "data")
#: The trace most tests read: the paper's 140 µm relaxation test, 1 % noise.
SEED_TRACE = os.path.join(DATA, "paper_dc140.csv")
PAPER = ["paper_dc126", "paper_dc140", "paper_dc154"]
#: A fitted parameter's name → the header key of its true value in data/'s synthetic traces.
TRUE = {"E_star": "true_E_star_Pa", "viscosity": "true_viscosity_Pa_s", "z0": "true_z0_m",
        "stiffening": "true_stiffening", "relaxation_time": "true_relaxation_time_s"}

#: The stepper's coarse run, one mesh with no contact-edge refinement (plans compared with relax
#: then share it): Settings keywords.
COARSE = dict(dr=0.05, mesh_growth=1.1, length=100.0, error_estimate=False, contact_radius=None)
#: The fit's coarse model (its mesh still refined at the contact edge).
FIT_COARSE = lubjax.Settings(dr=0.05, mesh_growth=1.2, length=100.0, error_estimate=False)

#: Every drive and substrate through one code path: (relax keywords, β, z̄0, field compared).
SCENES = {
    "load": (dict(drive=lubjax.Load()), 10.0, 0.5, "gap"),
    "spring": (dict(drive=lubjax.Spring(stiffness=2.0)), 100.0, 0.5, "force"),
    "free sphere": (dict(drive=lubjax.FreeSphere(inverse_mass=5.0)), 100.0, 1.0, "gap"),
    "viscoelastic": (
        dict(substrate=lubjax.Viscoelastic.standard_linear_solid(3.0, 1.0)), 100.0, 0.5, "force"
    ),
    "layer": (dict(substrate=lubjax.Layer(1.0, 0.5, "bonded")), 100.0, 0.5, "force"),
}


def data_path(stem, clean=False):
    """data/STEM.csv, or with ``clean`` its noiseless twin data/clean/STEM_clean.csv."""
    if clean:
        return os.path.join(DATA, "clean", f"{stem}_clean.csv")
    return os.path.join(DATA, f"{stem}.csv")


def read_data(stem, clean=False):
    return fitting.read_trace(data_path(stem, clean))


def short_trace(stem, t_bar, clean=True):
    """The trace cut to t̄ ≤ ``t_bar`` after its start, with the scales of the cut trace."""
    tr = cut_trace(read_data(stem, clean), t_bar)
    return tr, fitting.scales_from_trace(tr)


def truth(trace, names=("E_star", "viscosity", "z0")):
    """The true values in a synthetic trace's header, by parameter name."""
    return {n: float(trace.metadata[TRUE[n]]) for n in names}


# The accuracy table's converged reference (benchmarks/accuracy.py, its "ref" runs), read from
# its cache in benchmarks/out/cache/ (committed), computed there if missing: the same settings,
# output times and file names.
ACCURACY_T_END = 1e3
ACCURACY_T_OUT = np.unique(np.concatenate([np.linspace(0.01, 5.0, 500),
                                           np.geomspace(5.0, ACCURACY_T_END, 200)]))
ACCURACY_REFERENCE = lubjax.Settings(
    rtol=1e-7, dr=0.005, mesh_growth=1.05, length=2000.0, atol=1e-16, max_steps=400_000,
    error_estimate=False, contact_radius="auto", rim_refinement=7.0, contact_refinement=2.0)
_FIELDS = ("force", "film_center", "film_min")


def accuracy_reference(beta, z0):
    from lubjax._discretisation import DISCRETISATION
    from lubjax._mesh import final_contact_radius

    s = ACCURACY_REFERENCE
    rim = final_contact_radius(lubjax.as_drive(lubjax.RampHold()), z0, s.mesh_parameters()[0])
    key = repr((s.rtol, s.atol, s.mesh(rim).nodes, ACCURACY_T_END, DISCRETISATION)).encode()
    path = os.path.join(ROOT, "benchmarks", "out", "cache",
                        f"ref_b{beta:g}_z{z0:g}_{hashlib.sha1(key).hexdigest()[:10]}.npz")
    if os.path.exists(path):
        cached = np.load(path)
        if cached["t"].shape == ACCURACY_T_OUT.shape and np.allclose(cached["t"], ACCURACY_T_OUT):
            return {f: cached[f] for f in _FIELDS}
    res = lubjax.relax(beta, z0, ACCURACY_T_END, settings=s)
    out = {f: res.at(ACCURACY_T_OUT, f) for f in _FIELDS}
    os.makedirs(os.path.dirname(path), exist_ok=True)
    np.savez(path, t=ACCURACY_T_OUT, **out)
    return out


# --------------------------------------------------------------------------- vendor files

#: The pinned source distributions whose tests/ and examples/ hold real instrument files.
SDISTS = {"afmformats": "0.18.7", "nanite": "4.2.3"}


def vendor_cache() -> Path:
    """Where the sdists' instrument files are kept: ``LUBJAX_TESTDATA``, default
    ~/.cache/lubjax/testdata."""
    return Path(os.environ.get("LUBJAX_TESTDATA", Path.home() / ".cache/lubjax/testdata"))


def vendor_data() -> Path:
    """The instrument files of the pinned sdists, extracted once into :func:`vendor_cache`
    (``pytest.skip`` without the package index).

    Each sdist is downloaded and extracted into a private folder, then renamed into place:
    test workers running at once (pytest -n) never see half a folder."""
    import pytest

    root = vendor_cache()
    root.mkdir(parents=True, exist_ok=True)
    for name, version in SDISTS.items():
        final = root / f"{name}-{version}"
        if final.is_dir():
            continue
        with tempfile.TemporaryDirectory(dir=root) as tmp:
            cmd = [sys.executable, "-m", "pip", "download", "-q", "--no-deps", "--no-binary",
                   ":all:", "-d", tmp, f"{name}=={version}"]
            run = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
            archive = Path(tmp) / f"{name}-{version}.tar.gz"
            if run.returncode != 0 or not archive.exists():
                pytest.skip(f"the package index is not reachable (pip download {name}=="
                            f"{version} failed): {run.stderr.strip()[-200:]}")
            with tarfile.open(archive) as tar:
                members = [m for m in tar.getmembers() if m.isfile() and (
                    "/tests/data/" in m.name or "/examples/data/" in m.name)]
                tar.extractall(tmp, members=members, filter="data")
            for zipped in (Path(tmp) / final.name).glob("tests/data/fmt-chiaro-*.zip"):
                with zipfile.ZipFile(zipped) as z:
                    z.extractall(zipped.parent)
            try:
                os.rename(Path(tmp) / final.name, final)
            except OSError:  # another worker was first
                if not final.is_dir():
                    raise
    return root

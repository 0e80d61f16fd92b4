"""Is a fitted (or starting) E*, η, ramp speed that of a soft lubricated contact at all?

A column in the wrong unit does not stop a fit: force in mN read as N fits to an E* and an η
1000 times too large, and converges. The ranges below are far outside every soft lubricated
contact the model is for, so a value outside them points to a unit slip, and the flag names the
likely one with its fix:

* E* in [1 kPa, 1 GPa]: from the softest hydrogels to stiff rubbers and polymers; glass and metals
  (tens of GPa) are not soft contacts (from 1 Pa for AFM files: cells and tissue). E* ∝ force,
  so E* far above means the force is in mN (μN, nN) rather than N.
* η in [1e-4, 1e4] Pa s: from below water (1e-3) to 10x a 10⁶ cSt silicone oil (~1e3); the
  stiffest silicone gums (~2e4) are flagged too, the price of catching a time in ms on a
  100 Pa s oil (η = 1e5). η ∝ force × time: η high with E* high is the force's unit, η high
  alone the time's (ms read as s makes η 1000x larger, E* unchanged).
* the ramp speed d_c/t_c in [1 nm/s, 1 m/s]: no indenter or tribometer ramps outside it.

The checks flag; they never refuse (a fit may be right about an unusual sample).
"""

from __future__ import annotations

import math

E_STAR_RANGE_PA = (1e3, 1e9)
#: For AFM and indenter vendor files (fitting._afm; SI from the instrument, no unit to slip):
#: cells and tissue go down to ~10 Pa.
AFM_E_STAR_RANGE_PA = (1.0, 1e9)
VISCOSITY_RANGE_PA_S = (1e-4, 1e4)
SPEED_RANGE_M_S = (1e-9, 1.0)
_PREFIX = {"force": ("N", "mN", "uN", "nN"), "time": ("s", "ms", "us", "ns")}


def _slip(x: float, lo: float, hi: float) -> int:
    """k > 0 when x is above hi by up to 1000^k, k < 0 when below lo by up to 1000^|k|, else 0."""
    if not math.isfinite(x) or x <= 0:
        return 0
    if x > hi:
        return max(1, math.ceil(math.log(x / hi) / math.log(1000) - 1e-9))
    if x < lo:
        return -max(1, math.ceil(math.log(lo / x) / math.log(1000) - 1e-9))
    return 0


def _si(x: float, unit: str) -> str:
    """x with an SI prefix: 1.503e9 Pa -> '1.503 GPa'."""
    if not (math.isfinite(x) and x > 0):
        return f"{x:.4g} {unit}"
    k = max(-3, min(4, math.floor(math.log10(x) / 3)))
    return f"{x / 1000.0**k:.4g} {'nμm kMGT'[k + 3].strip()}{unit}"


def _unit_fix(what: str, k: int) -> str:
    """The unit slip of ``what`` (force or time) by a factor 1000^k and its --units fix."""
    units = _PREFIX[what]
    if 0 < k < len(units):
        return f"is the {what} in {units[k]} rather than {units[0]}? use --units {what}={units[k]}"
    if k > 0:
        return f"is the {what} column in a much smaller unit than read? check --units {what}=..."
    return (f"is the {what} read in a smaller unit than it is in (e.g. declared {units[1]} but in "
            f"{units[0]})? check --units and the header")


def e_star_range(metadata) -> tuple[float, float]:
    """The plausible E* of a trace: ``AFM_E_STAR_RANGE_PA`` for a vendor file read by
    fitting._afm (its metadata has ``instrument_file``), else ``E_STAR_RANGE_PA``."""
    return AFM_E_STAR_RANGE_PA if "instrument_file" in (metadata or {}) else E_STAR_RANGE_PA


def plausibility_flags(values: dict, speed: float | None = None,
                       e_range: tuple[float, float] = E_STAR_RANGE_PA) -> list[str]:
    """Messages for values outside soft lubricated contact (empty when all are inside).

    Args:
        values: parameter values in SI (``E_star`` [Pa], ``viscosity`` [Pa s]; others ignored).
        speed: the ramp speed d_c/t_c [m/s] (``Scales.speed``), or None.
        e_range: the plausible E* [Pa] (:func:`e_star_range` of the trace's metadata).
    """
    flags = []
    lo, hi = e_range
    kE = _slip(values.get("E_star", math.nan), lo, hi)
    if kE:
        E = values["E_star"]
        where = (f"above {_si(hi, 'Pa')}, the top" if kE > 0
                 else f"below {_si(lo, 'Pa')}, the bottom")
        flags.append(f"E* = {_si(E, 'Pa')} is {where} of soft lubricated contact: "
                     f"{_unit_fix('force', kE)}")
    lo, hi = VISCOSITY_RANGE_PA_S
    kv = _slip(values.get("viscosity", math.nan), lo, hi)
    if kv:
        eta = values["viscosity"]
        where = f"above {hi:g} Pa s, the top" if kv > 0 else f"below {lo:g} Pa s, the bottom"
        if kE and (kE > 0) == (kv > 0):
            why = f"{_unit_fix('force', kE)} (E* is off the same way)"
        else:
            why = _unit_fix("time", kv)
        flags.append(f"eta = {eta:.4g} Pa s is {where} of lubricating films: {why}")
    if speed is not None:
        lo, hi = SPEED_RANGE_M_S
        ks = _slip(speed, lo, hi)
        if ks:
            where = f"below {_si(lo, 'm/s')}" if ks < 0 else f"above {_si(hi, 'm/s')}"
            flags.append(f"the ramp speed d_c/t_c = {speed:.4g} m/s is {where}, outside any "
                         f"instrument: {_unit_fix('time', -ks)}")
    return flags

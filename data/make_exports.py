"""Write data/exports/: data/paper_dc140.csv as three other programs might export it, for the
examples of reading exports (data/README.md, "Instrument exports"). Every second row is kept.

* ``export.txt``: a vendor's tab-separated export: an instrument header block, the radius as a
  ``# radius_m:`` line, columns ``Time (s)``, ``Piezo (nm)``, ``Load (uN)`` and a temperature
  column that is not read (``--columns`` by header name);
* ``noheader.csv``: no header row, time [s], travel [µm], force [mN] (``--columns`` by number,
  ``--units``);
* ``negative_mN_ms.csv``: time in ms and force in mN named in the header, compression recorded
  as a negative force (``--units``, ``--force-sign -1``).

Run: ``python data/make_exports.py``.
"""

from __future__ import annotations

import os

HERE = os.path.dirname(os.path.abspath(__file__))


def main() -> None:
    import fitting

    tr = fitting.read_trace(os.path.join(HERE, "paper_dc140.csv"))
    t, d, f = tr.time[::2], tr.displacement[::2], tr.force[::2]
    radius = f"# radius_m: {tr.radius:g}\n"
    out = os.path.join(HERE, "exports")
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "export.txt"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write("Instrument: tribometer (synthetic: data/paper_dc140.csv)\n"
                 "Operator: -\n" + radius + "Time (s)\tPiezo (nm)\tLoad (uN)\tTemperature (C)\n")
        for a, b, c in zip(t, d, f):
            fh.write(f"{a:.4f}\t{b * 1e9:.4f}\t{c * 1e6:.5g}\t21.0\n")
    with open(os.path.join(out, "noheader.csv"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write(radius)
        for a, b, c in zip(t, d, f):
            fh.write(f"{a:.4f},{b * 1e6:.7g},{c * 1e3:.6g}\n")
    with open(os.path.join(out, "negative_mN_ms.csv"), "w", encoding="utf-8",
              newline="\n") as fh:
        fh.write(radius + "time_ms,displacement_m,force_mN\n")
        for a, b, c in zip(t, d, f):
            fh.write(f"{a * 1e3:.1f},{b:.7e},{-c * 1e3:.6g}\n")


if __name__ == "__main__":
    main()

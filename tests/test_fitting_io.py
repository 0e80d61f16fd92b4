"""The trace CSV reader/writer: round trip, bundled files, and errors that name line and column."""

import glob
import os
import zipfile

import numpy as np
import pytest

from fitting import format_trace, make_trace, parse_trace, read_trace, scales_from_trace

from helpers import DATA

HEADER = "# radius_m: 2.0e-3\n# poisson_ratio: 0.5\n# sample: bead 3\n"


def _rows(n=12, start=0):
    return "".join(f"{0.1 * k},{1e-6 * max(k - 2, 0)},{1e-3 * k}\n" for k in range(start, n))


def _text(header=HEADER, cols="time_s,displacement_m,force_N\n", rows=None):
    return header + cols + (_rows() if rows is None else rows)


def test_parse_valid_trace_keeps_metadata():
    tr = parse_trace(_text(), name="x.csv")
    assert tr.radius == pytest.approx(2e-3)
    assert tr.metadata["poisson_ratio"] == "0.5"
    assert tr.metadata["sample"] == "bead 3"
    assert tr.time.size == 12 and tr.force[3] == pytest.approx(3e-3)


def test_columns_in_any_order():
    rows = "".join(f"{1e-3 * k},{0.1 * k},{1e-6 * k}\n" for k in range(12))
    tr = parse_trace(_text(cols="force_N,time_s,displacement_m\n", rows=rows))
    np.testing.assert_allclose(tr.time, 0.1 * np.arange(12))
    np.testing.assert_allclose(tr.displacement, 1e-6 * np.arange(12))


def test_round_trip():
    tr = parse_trace(_text(), name="a")
    back = parse_trace(format_trace(tr), name="b")
    np.testing.assert_allclose(back.time, tr.time)
    np.testing.assert_allclose(back.displacement, tr.displacement, rtol=1e-7)
    np.testing.assert_allclose(back.force, tr.force, rtol=1e-6)
    assert back.metadata == tr.metadata


@pytest.mark.parametrize(
    "text, match",
    [
        (_text(header="# poisson_ratio: 0.5\n"), r"missing '# radius_m"),
        (_text(header="# radius_m: big\n"), r"line 1: radius_m must be a positive number"),
        (_text(header="# radius_m: -1\n"), r"line 1: radius_m must be finite and > 0"),
        (_text(cols="time_s,displacement_m\n"), r"line 4: missing column\(s\) force_N"),
        (
            _text(cols="time_s,displacement_m,force_N,temp_C\n"),
            r"line 4, column 4: unknown column 'temp_C'",
        ),
        (_text(cols="time_s,time_s,force_N\n"), r"line 4, column 2: duplicate column 'time_s'"),
        (
            _text(rows=_rows(6) + "0.6,abc,0.1\n" + _rows(12, 7)),
            r"line 11, column 2 \(displacement_m\): 'abc' is not a number",
        ),
        (
            _text(rows=_rows(6) + "0.6,1e-6,nan\n" + _rows(12, 7)),
            r"line 11, column 3 \(force_N\): 'nan' is not finite",
        ),
        (_text(rows=_rows(6) + "0.6,1e-6\n" + _rows(12, 7)), r"line 11: expected 3 cells"),
        (
            _text(rows=_rows(6) + "0.5,1e-6,0.1\n" + _rows(12, 7)),
            r"line 11, column 1 \(time_s\): time 0.5 is not greater",
        ),
        (_text(rows=_rows(5)), r"at least 10 data rows"),
        (HEADER, r"no header row"),
        (_text() + "# late: 1\n", r"line 17: '# key: value' lines must come before the header"),
    ],
)
def test_malformed_files_name_line_and_column(text, match):
    with pytest.raises(ValueError, match=match):
        parse_trace(text, name="bad.csv")


def test_error_names_the_file(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text(_text(rows=_rows(6) + "0.6,x,0.1\n" + _rows(12, 7)))
    with pytest.raises(ValueError, match=r"t\.csv: line 11, column 2"):
        read_trace(p)
    with pytest.raises(ValueError, match="cannot read"):
        read_trace(tmp_path / "missing.csv")


def test_make_trace_validates():
    t = np.arange(12.0)
    with pytest.raises(ValueError, match="row 3, column 'force_N'"):
        make_trace(t, t, np.where(t == 3, np.nan, t), 1e-3)
    with pytest.raises(ValueError, match="time_s"):
        make_trace(t[::-1], t, t, 1e-3)
    with pytest.raises(ValueError, match="radius_m"):
        make_trace(t, t, t, 0.0)


def test_no_motion_is_an_error():
    rows = "".join(f"{0.1 * k},0.0,{1e-3 * k}\n" for k in range(12))
    tr = parse_trace(_text(rows=rows))
    with pytest.raises(ValueError, match="displacement_m"):
        scales_from_trace(tr)


def test_position_control_may_end_on_its_ramp_load_control_may_not():
    """An AFM approach ends at its deepest point (no hold): the motion ends with the record.
    Load control still needs the hold (the creep start takes the final approach from it)."""
    t = np.linspace(0.0, 1.0, 101)
    d = np.where(t < 0.2, 0.0, 1e-6 * (t - 0.2))
    f = 1e-2 * np.clip(d - 4e-7, 0.0, None) ** 1.5
    sc = scales_from_trace(make_trace(t, d, f, 1e-4))
    assert sc.t_on == pytest.approx(0.2)
    assert sc.t_end_motion == pytest.approx((t[-1] - sc.t_on) / sc.time_scale)
    with pytest.raises(ValueError, match="never settles into a hold"):
        scales_from_trace(make_trace(t, d, 1e-9 + d, 1e-4, {"drive": "force"}))


def test_bundled_traces_are_valid_and_small():
    files = sorted(
        glob.glob(os.path.join(DATA, "*.csv")) + glob.glob(os.path.join(DATA, "clean", "*.csv"))
    )
    assert len(files) >= 4
    for path in files:
        assert os.path.getsize(path) < 1_000_000
        tr = read_trace(path)
        s = scales_from_trace(tr)
        # dc and v0 (the load and its ramp) come from the data: they match the generator's truth.
        if tr.metadata.get("drive") == "force":
            assert s.input_end == pytest.approx(float(tr.metadata["true_load_N"]), rel=1e-3)
            assert s.time_scale == pytest.approx(float(tr.metadata["load_ramp_s"]), rel=1e-2)
        else:
            assert s.indent == pytest.approx(float(tr.metadata["true_indent_m"]), rel=1e-3)
            assert s.speed == pytest.approx(float(tr.metadata["true_speed_m_s"]), rel=1e-2)
        assert s.t_on == pytest.approx(float(tr.metadata["motion_start_s"]), abs=0.05)


@pytest.mark.parametrize("header, match", [
    ("# radius_m: 2e-3\n# drive: pull\n", r"line 2: drive must be one of travel, spring, force"),
    ("# radius_m: 2e-3\n# stiffness_N_m: -5\n", r"line 2: stiffness_N_m .* must be a finite"),
    ("# radius_m: 2e-3\n# stiffness_N_m: stiff\n", r"line 2: stiffness_N_m"),
])
def test_model_header_keys_are_checked(header, match):
    with pytest.raises(ValueError, match=match):
        parse_trace(_text(header=header), name="x.csv")


def test_model_header_keys_are_kept():
    tr = parse_trace(_text(header="# radius_m: 2e-3\n# drive: force\n# stiffness_N_m: 5e3\n"))
    assert tr.metadata["drive"] == "force" and tr.meta_float("stiffness_N_m") == 5e3


@pytest.mark.parametrize("text, what", [("", "is empty"),
                                        (" \n\n\t\r\n", "holds only blank lines")])
def test_an_empty_file_says_so(text, what, tmp_path):
    message = f"the file {what}: no header row, no data"
    with pytest.raises(ValueError, match=f"^bad.csv: {message}$"):
        parse_trace(text, name="bad.csv")
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(ValueError, match=f"^{p}: {message}$"):
        read_trace(p)


def _zip(path, files: dict):
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path


def test_a_zipped_trace_is_read_as_the_file_inside(tmp_path):
    """A zipped export (a folder in it and macOS's additions do not count) reads as its file."""
    seed = os.path.join(DATA, "paper_dc140.csv")
    text = open(seed, encoding="utf-8").read()
    z = _zip(tmp_path / "export.zip", {"run/": b"", "run/trace.csv": text,
                                        "__MACOSX/run/._trace.csv": b"\x00\x05\x16\x07",
                                        "run/.DS_Store": b"\x00\x00\x00\x01Bud1"})
    tr, ref = read_trace(z), read_trace(seed)
    assert tr.name == f"{z}/run/trace.csv"
    for a, b in zip(tr[:3], ref[:3]):
        np.testing.assert_array_equal(a, b)
    assert tr.radius == ref.radius and tr.metadata == ref.metadata


def test_a_zip_that_is_not_one_export_is_refused_naming_what_it_holds(tmp_path):
    rows = _text()
    many = {f"curve{k}.csv": rows for k in range(6)}
    with pytest.raises(ValueError, match=r"a zip archive holding 2 files \(a\.csv, b\.csv\): "
                       r"unzip it and give the file\(s\) to read$"):
        read_trace(_zip(tmp_path / "two.zip", {"a.csv": rows, "b.csv": rows}))
    with pytest.raises(ValueError, match=r"holding 6 files \(curve0\.csv, curve1\.csv, "
                       r"curve2\.csv, curve3\.csv, \.\.\. \(6 files\)\)"):
        read_trace(_zip(tmp_path / "six.zip", many))
    with pytest.raises(ValueError, match=r"cell\.jpk-force: a JPK AFM file, not a trace file: "
                       r"read it with fitting\.read_afm"):
        read_trace(_zip(tmp_path / "cell.jpk-force", {"header.properties": "", "segments/": ""}))
    with pytest.raises(ValueError, match=r"none\.zip: a zip archive with no file in it$"):
        read_trace(_zip(tmp_path / "none.zip", {"folder/": b""}))
    # a member whose bytes do not match its checksum
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w", zipfile.ZIP_STORED) as z:
        z.writestr("t.csv", rows)
    raw = bytearray(bad.read_bytes())
    at = raw.index(rows[:20].encode())
    raw[at] ^= 1
    bad.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"bad\.zip: a zip archive that cannot be read \(Bad "
                       r"CRC-32 .*\): unzip it"):
        read_trace(bad)


def test_a_zipped_vendor_export_is_an_afm_file(tmp_path):
    """lubjax-fit sends a zip to afmformats when the one file in it is a vendor export."""
    from fitting._afm import is_afm_file

    assert is_afm_file(_zip(tmp_path / "c.zip", {"c.txt": "# Optics11 Chiaro export\n"}))
    assert is_afm_file(_zip(tmp_path / "j.zip", {"cell.jpk-force": b"PK\x03\x04"}))
    assert not is_afm_file(_zip(tmp_path / "t.zip", {"t.txt": _text()}))
    assert not is_afm_file(_zip(tmp_path / "two.zip", {"a.jpk-force": "", "b.jpk-force": ""}))

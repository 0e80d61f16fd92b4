"""Safe outputs and one-line errors for the command lines (``lubjax``, ``lubjax-fit``).

* :func:`check_outputs` validates every output path (non-empty, not a folder or a device, a
  known plot format) and refuses an output that is an input file or another output of the same
  run (resolved paths, hard links included); :func:`prepare_outputs` then creates the folders
  and proves they take a new file. The command lines call both *before* any computation.
* :func:`atomic_open` writes to a temporary file in the target's folder and renames it over the
  target only once everything is written: a failed write leaves the old file as it was.
* :class:`Parser` and :func:`run_cli` give each failure one line on stderr and an exit status:
  ``EXIT_USAGE`` (2) for bad usage or input, ``EXIT_FAILED`` (1) for a run that failed.
* :func:`read_load_csv` reads the load history of ``lubjax creep --load-csv`` (the traces of
  ``lubjax-fit`` are read by :mod:`fitting._csv`, which lubjax does not import).

The options the two command lines share are in :mod:`lubjax._cli_options`; ``fitting`` may
import both modules.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import stat
import sys
import tempfile
import traceback

import numpy as np

EXIT_OK = 0
EXIT_FAILED = 1  # the run failed: solver error, fit not converged, an output not written
EXIT_USAGE = 2  # bad usage or input: nothing was computed and nothing written

#: Plot formats matplotlib writes (by file extension); anything else is refused up front.
PLOT_FORMATS = ("png", "pdf", "svg", "svgz", "eps", "ps", "jpg", "jpeg", "tif", "tiff", "webp")

EXIT_EPILOG = """\
exit status:
  0  success
  1  the run failed: {failed}
  2  bad usage or input: found before any computation, nothing written

Each error is one line on stderr (--debug: the traceback instead).
Outputs are checked before the run (writable, not an input file, not
another output, known plot format) and written to a temporary file
that is then renamed: a failed write leaves the old file as it was."""


class UsageError(ValueError):
    """Bad usage or input: exit status 2, nothing computed or written."""


class WriteError(OSError):
    """An output could not be written (the previous file, if any, is untouched): exit 1."""


def one_line(message) -> str:
    """``message`` with its lines joined by " / " (an error is one line on stderr)."""
    parts = [part.strip() for part in str(message).splitlines()]
    return " / ".join(part for part in parts if part) or "(no message)"


# --------------------------------------------------------------------------- argument parsing

# argparse takes "-3.9e6" for an option (its own pattern lacks exponents): accept any number.
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.I)


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (raised as :class:`UsageError`) and negative numbers with
    exponents accepted as option values (``--E-star -3.9e6`` reaches the range check)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)
        if hasattr(self, "_negative_number_matcher"):
            self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message):
        raise UsageError(f"{message} (see {self.prog} --help)")


def run_cli(prog: str, parser: argparse.ArgumentParser, body, argv=None) -> int:
    """Parse ``argv`` and run ``body(args)``; every failure becomes one line on stderr.

    Returns the exit status: ``body``'s, 2 for a :class:`ValueError` (bad usage or input), 1 for
    any other error (a failed run, an output that could not be written). With ``--debug`` the
    exception propagates with its traceback.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in argv
    try:
        args = parser.parse_args(argv)
        return body(args)
    except SystemExit as exc:  # --help; sys.exit("message") from below
        if exc.code is None or isinstance(exc.code, int):
            return exc.code or EXIT_OK
        print(f"{prog}: error: {one_line(exc.code)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        if debug:
            raise
        if isinstance(exc, ValueError):
            code, text = EXIT_USAGE, str(exc)
        elif isinstance(exc, (WriteError, RuntimeError)):
            code, text = EXIT_FAILED, str(exc)
        else:  # a bug: say where, briefly
            where = traceback.extract_tb(exc.__traceback__)[-1]
            code = EXIT_FAILED
            text = (
                f"internal error {type(exc).__name__}: {exc} "
                f"(at {os.path.basename(where.filename)}:{where.lineno}; rerun with --debug)"
            )
        print(f"{prog}: error: {one_line(text)}", file=sys.stderr)
        return code


# --------------------------------------------------------------------------- output checks


def plot_format(path: str) -> str:
    """The format of a plot file from its extension; UsageError unless matplotlib writes it."""
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    allowed = ", ".join("." + f for f in PLOT_FORMATS)
    if not ext:
        raise UsageError(f"plot file {path!r} has no extension: name the format, one of {allowed}")
    if ext not in PLOT_FORMATS:
        raise UsageError(f"plot file {path!r}: unknown format '.{ext}' (use one of {allowed})")
    return ext


def _check_writable(option: str, path: str) -> None:
    if path == "" or not path.strip():
        raise UsageError(f"{option}: empty file name")
    if path.endswith(("/", os.sep)) or os.path.isdir(path):
        raise UsageError(f"{option} {path}: is a folder; give a file name")
    if os.path.lexists(path) and not os.path.isfile(path):
        raise UsageError(
            f"{option} {path}: exists and is not a regular file (a device, socket or broken "
            "link); refusing to replace it"
        )
    if os.path.isfile(path) and not os.access(path, os.W_OK):
        raise UsageError(f"{option} {path}: the file is read-only; refusing to replace it")


def _probe_folder(option: str, path: str) -> None:
    """Create the output's folder if missing and create (then remove) a file in it: the only
    check that also catches read-only file systems and special folders, as root too."""
    folder = os.path.dirname(os.path.realpath(path))
    try:
        os.makedirs(folder, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".lubjax-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UsageError(
            f"{option} {path}: cannot write in folder {folder} ({exc.strerror or exc})"
        ) from None


def _same_file(a: str, b: str) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)  # hard links; only when both exist
    except OSError:
        return False


def check_outputs(outputs, inputs=(), input_label="input file") -> None:
    """Validate the outputs of one run before computing anything.

    Args:
        outputs: ``(option, path)`` pairs, e.g. ``("--out", "fit.json")``; ``path`` None skips
            it. Options named ``--plot`` must carry a plot extension (:data:`PLOT_FORMATS`).
        inputs: paths read by the run: no output may be one of them.
        input_label: what an input is called in the message.

    Raises:
        UsageError: naming the option, the path and what is wrong.
    """
    given = [(opt, path) for opt, path in outputs if path is not None]
    for opt, path in given:
        _check_writable(opt, path)
        if opt.startswith("--plot"):
            plot_format(path)
    for opt, path in given:
        for src in inputs:
            if _same_file(path, src):
                raise UsageError(
                    f"{opt} {path} is the {input_label} {src}: refusing to overwrite an input "
                    "(choose another file name)"
                )
    for i, (opt, path) in enumerate(given):
        for opt2, path2 in given[:i]:
            if _same_file(path, path2):
                raise UsageError(
                    f"{opt} {path} and {opt2} {path2} are the same file: give each output its "
                    "own name"
                )


def prepare_outputs(outputs) -> None:
    """Create the outputs' missing folders and prove each can take a new file (UsageError if
    not). Call it after :func:`check_outputs` and the input checks, just before computing: it is
    the only check with a side effect (the folders it creates)."""
    for opt, path in outputs:
        if path is not None:
            _probe_folder(opt, path)


def check_distinct_inputs(inputs, label="input file") -> None:
    """UsageError if the same file is given twice."""
    for i, path in enumerate(inputs):
        for other in inputs[:i]:
            if _same_file(path, other):
                raise UsageError(f"{label} {path} is given twice ({other})")


# --------------------------------------------------------------------------- atomic writes


def _new_file_mode(target: str) -> int:
    try:
        return stat.S_IMODE(os.stat(target).st_mode)  # replacing: keep its permissions
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", **kwargs):
    """Open ``path`` for writing through a temporary file in the same folder.

    The temporary file is synced and renamed over ``path`` when the ``with`` block ends
    without error; on any error it is removed and ``path`` is untouched. A symbolic link is
    written through (its target is replaced). Creates missing folders. Raises
    :class:`WriteError` (an ``OSError``) naming the path on a failed write.
    """
    path = os.fspath(path)
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes only ('w' or 'wb'), got mode {mode!r}")
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
    target = os.path.realpath(path)
    folder = os.path.dirname(target)
    tmp = None
    try:
        os.makedirs(folder, exist_ok=True)
        fd, tmp = tempfile.mkstemp(
            dir=folder, prefix="." + os.path.basename(target) + ".", suffix=".tmp"
        )
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, _new_file_mode(target))
        os.replace(tmp, target)
        tmp = None
    except OSError as exc:
        raise WriteError(
            f"cannot write {path}: {exc.strerror or exc} (any previous file is unchanged)"
        ) from exc
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_open(path, "w") as fh:
        fh.write(text)


def save_figure(fig, path, **kwargs) -> None:
    """``fig.savefig`` to ``path`` atomically, in the format its extension names."""
    fmt = plot_format(os.fspath(path))
    with atomic_open(path, "wb") as fh:
        fig.savefig(fh, format=fmt, **kwargs)


def read_load_csv(path):
    """(time_s, force_N) from a CSV with a header line naming time_s and force_N; a malformed
    value names its line and column."""
    try:
        with open(path, encoding="utf-8-sig") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise UsageError(f"--load-csv {path}: cannot read it ({e})") from None
    rows = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    if not rows:
        raise UsageError(f"{path}: no data")
    header = [h.strip() for h in rows[0][1].split(",")]
    if "time_s" not in header or "force_N" not in header:
        raise UsageError(
            f"{path}:{rows[0][0]}: the header must name time_s and force_N, got {header}")
    it, jf = header.index("time_s"), header.index("force_N")
    t, f = [], []
    for lineno, ln in rows[1:]:
        cells = ln.split(",")
        if len(cells) != len(header):
            raise UsageError(f"{path}:{lineno}: {len(cells)} columns, the header has {len(header)}")
        for col, out in ((it, t), (jf, f)):
            try:
                v = float(cells[col])
            except ValueError:
                raise UsageError(
                    f"{path}:{lineno}: column {col + 1} ({header[col]}) is not a number: "
                    f"{cells[col].strip()!r}"
                ) from None
            if not math.isfinite(v):
                raise UsageError(f"{path}:{lineno}: column {col + 1} ({header[col]}) is {v}")
            out.append(v)
    t, f = np.asarray(t), np.asarray(f)
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise UsageError(f"{path}: time_s must increase strictly over at least two rows")
    if f.max() <= 0 or f.min() < 0:
        raise UsageError(f"{path}: force_N must be >= 0 with a positive peak (a compressive load)")
    return t, f

"""Every documented ``lubjax`` and ``lubjax-fit`` command runs as written.

The commands are read from README.md, data/README.md and docs/**/*.md: each line of a fenced
block (any language, indented ones in lists too; backslash continuations joined) that runs
``lubjax`` or ``lubjax-fit`` (after a ``pip install ... &&``, which is left out), and each
inline ``lubjax-fit ...`` that names a trace under data/ (other inline mentions, such as
``lubjax-fit --drive``, are fragments of a sentence). A command found on several pages runs
once.

Each runs in bash, as a reader would type it, in a scratch folder that sees the repository's
``data/`` (so nothing is written into the repository), with the installed entry points of this
Python and a compilation cache of its own shared by the commands. Checked: the exit status, a
key line of the output (a fit's summary line, a run's result line) and a ``wrote PATH`` line and
the file for each output asked for. The AFM page's commands name instrument files of the
afmformats and nanite sdists (tests/helpers.vendor_data): linked into the folder under the
names the page uses; without afmformats or the package index they skip.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import pytest

from helpers import ROOT, SDISTS, vendor_data

PAGES = sorted([Path(ROOT) / "README.md", Path(ROOT) / "data" / "README.md",
                *(Path(ROOT) / "docs").rglob("*.md")])
FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>```+)[^\n`]*\n(?P<body>.*?)"
                   r"^(?P=indent)(?P=fence)[ \t]*$", re.MULTILINE | re.DOTALL)
INLINE = re.compile(r"(?<!`)`(lubjax-fit [^`]*\bdata/[^`]*)`(?!`)")
COMMAND = re.compile(r"^(?:[A-Z_]+=\S+\s+)*lubjax(?:-fit)?\s")

#: Instrument files the AFM page names, where they lie in the sdists (helpers.vendor_data).
VENDOR = {
    "zebrafish-head-section-gray-matter.jpk-force":
        f"nanite-{SDISTS['nanite']}/examples/data/zebrafish-head-section-gray-matter.jpk-force",
    "fmt-jpk-cc_pr14-polymergel-2021.06.30.jpk-force":
        f"afmformats-{SDISTS['afmformats']}/tests/data/"
        "fmt-jpk-cc_pr14-polymergel-2021.06.30.jpk-force",
    "fmt-jpk-sr_cell1-0008.jpk-force":
        f"afmformats-{SDISTS['afmformats']}/tests/data/fmt-jpk-sr_cell1-0008.jpk-force",
}

#: Commands whose documented outcome is not exit status 0: (a piece of the command, the exit
#: status, a line the output must hold, as the page says).
DOCUMENTED = [
    ("--plot out/run.txt", 0, r"^exit status 2$"),  # errors.md: an unknown plot format
]
#: The suite runs the README's first command and the refusal of errors.md; every other command
#: runs with ``--doc-commands`` (tests/conftest.py), as CI does after the suite: 2-30 s each on
#: two cores, even with the compilation cache the commands share, about 7 minutes in all one
#: after another, more than the suite's budget.
FAST = ("lubjax-fit data/paper_dc140.csv --out out/fit.json --plot out/fit.png",
        "lubjax relax --beta 100 --z0 0.5 --plot out/run.txt; echo \"exit status $?\"")


class Command(NamedTuple):
    text: str
    where: str  # page:line of its first mention


def _command_lines(body: str) -> list[tuple[int, str]]:
    """(line index, command) of each shell line of a fenced block that runs lubjax or
    lubjax-fit."""
    out, lines, k = [], body.splitlines(), 0
    while k < len(lines):
        first, line = k, lines[k]
        while line.endswith("\\") and k + 1 < len(lines):  # a continued line
            k += 1
            line = line[:-1] + " " + lines[k]
        k += 1
        line = " ".join(line.split())
        # "pip install -e . && lubjax-fit ...": the install is the reader's set-up, not run here
        parts = line.split(" && ")
        while len(parts) > 1 and not COMMAND.match(parts[0]):
            parts = parts[1:]
        line = " && ".join(parts)
        if COMMAND.match(line):
            out.append((first, line))
    return out


def documented_commands() -> list[Command]:
    """Every documented lubjax / lubjax-fit command, once, with where it is first written."""
    found: dict[str, str] = {}
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        rel = page.relative_to(ROOT)
        for m in FENCE.finditer(text):
            indent = len(m.group("indent"))
            body = "\n".join(x[indent:] for x in m.group("body").splitlines())
            start = text.count("\n", 0, m.start()) + 2  # the block's first line, from 1
            for k, cmd in _command_lines(body):
                found.setdefault(cmd, f"{rel}:{start + k}")
        for m in INLINE.finditer(text):
            found.setdefault(m.group(1), f"{rel}:{text.count(chr(10), 0, m.start()) + 1}")
    return [Command(text, where) for text, where in found.items()]


COMMANDS = documented_commands()


def _marks(cmd: Command):
    marks = []
    if not cmd.text.startswith(FAST):
        marks += [pytest.mark.slow, pytest.mark.doc_command]
    return marks


def test_the_extractor_finds_the_documented_commands():
    # Guards against an extractor that silently finds nothing: commands of the README, a list
    # item's indented block, a continued line, an inline mention and a pip-prefixed line.
    texts = [c.text for c in COMMANDS]
    assert len(texts) >= 30
    assert "lubjax-fit data/paper_dc140.csv --out out/fit.json --plot out/fit.png" in texts
    assert any(t.startswith("lubjax-fit fmt-jpk-cc_pr14-polymergel") for t in texts)
    assert any(t.startswith("lubjax bounce") and "--plot out/bounce.png" in t for t in texts)
    assert "lubjax-fit data/paper_*.csv --out out/fits.json" in texts
    assert not any("pip install" in t for t in texts)
    body = "```bash\npip install -e . && lubjax relax --beta 1 \\\n    --z0 2  # note\nls\n```"
    assert _command_lines(body.split("\n", 1)[1].rsplit("```", 1)[0]) == [
        (0, "lubjax relax --beta 1 --z0 2 # note")]


@pytest.fixture(scope="module")
def compile_cache(tmp_path_factory) -> Path:
    """One compilation cache for the commands of this module (as a user's would be)."""
    return tmp_path_factory.mktemp("jax-cache")


def _outputs(cmd: str) -> list[str]:
    """The files a command is asked to write (--out, --plot, --table, --report)."""
    words = shlex.split(cmd.split(";")[0], comments=True)
    return [words[i + 1] for i, w in enumerate(words[:-1])
            if w in ("--out", "--plot", "--table", "--report")]


def _key_line(cmd: str) -> str:
    """A regular expression for the result line a command prints."""
    if cmd.startswith("lubjax-fit"):
        return r"^\S+: E\* = .*; beta = .*(converged|NOT CONVERGED)"
    return r"\b\d+ steps\b"  # relax, creep, bounce: "...; 438 steps (2 rejected), run ..."


@pytest.mark.parametrize("cmd", [pytest.param(c, marks=_marks(c), id=c.where) for c in COMMANDS])
def test_documented_command_runs(cmd, tmp_path, compile_cache):
    (tmp_path / "data").symlink_to(Path(ROOT) / "data", target_is_directory=True)
    named = [name for name in VENDOR if name in cmd.text]
    if named:
        pytest.importorskip("afmformats", reason="the AFM commands need: pip install lubjax[afm]")
        root = vendor_data()
        for name in named:
            (tmp_path / name).symlink_to(root / VENDOR[name])
    env = dict(os.environ, LUBJAX_CACHE="1", LUBJAX_CACHE_DIR=str(compile_cache),
               PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    run = subprocess.run(["bash", "-c", cmd.text], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=900)
    said = f"{cmd.where}: {cmd.text}\nstdout:\n{run.stdout}\nstderr:\n{run.stderr[-3000:]}"
    status, line, documented = 0, _key_line(cmd.text), False
    for piece, documented_status, documented_line in DOCUMENTED:
        if piece in cmd.text:
            status, line, documented = documented_status, documented_line, True
    assert run.returncode == status, said
    assert re.search(line, run.stdout, re.MULTILINE), said
    if not documented:
        for path in _outputs(cmd.text):
            stem, ext = os.path.splitext(path)
            written = [p for p in re.findall(r"^wrote (\S+)$", run.stdout, re.MULTILINE)
                       if p == path or (p.startswith(stem + "_") and p.endswith(ext))]
            assert written and all((tmp_path / p).is_file() for p in written), (path, said)

"""Every ```python block of README.md and docs/**/*.md runs.

A page's blocks run in order in one namespace (later blocks use earlier names), in a scratch
working folder that sees the repository's ``data/`` and has an empty ``out/``, so the examples'
paths work as written. A block is left out only when its fence has a title
(```python title="...") or the line before it is ``<!-- skip -->``: for fragments that cannot
run on their own (a different process's environment, a cluster).
"""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parent.parent
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])

#: An opening fence, its info string, the block, and the closing fence of the same length.
FENCE = re.compile(r"^(?P<fence>```+)(?P<info>[^\n`]*)\n(?P<body>.*?)^(?P=fence)[ \t]*$",
                   re.MULTILINE | re.DOTALL)
SKIP = "<!-- skip -->"


def python_blocks(text: str) -> list[tuple[int, str]]:
    """(line number, source) of each runnable python block of a Markdown text."""
    blocks = []
    for m in FENCE.finditer(text):
        info = m.group("info").strip().split()
        if not info or info[0] != "python" or any(w.startswith("title=") for w in info[1:]):
            continue
        before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1].strip()
        if before == SKIP:
            continue
        blocks.append((text.count("\n", 0, m.start()) + 2, m.group("body")))
    return blocks


def test_the_extractor_sees_fences_titles_and_skips():
    text = (
        "```python\na = 1\n```\n"
        "```python title=\"x.py\"\nb = 2\n```\n"
        "<!-- skip -->\n```python\nc = 3\n```\n"
        "````markdown\n```python\nd = 4\n```\n````\n"
        "```bash\nls\n```\n"
    )
    assert [src for _, src in python_blocks(text)] == ["a = 1\n"]


def test_the_main_pages_have_examples():
    # Guards against an extractor that silently finds nothing.
    for name in ("README.md", "docs/getting-started.md", "docs/guide/simulating.md",
                 "docs/guide/fitting.md"):
        assert python_blocks((ROOT / name).read_text(encoding="utf-8")), name


@pytest.mark.slow  # runs what a reader would (5-25 s a page): with --doc-commands, as CI does
@pytest.mark.doc_command
@pytest.mark.parametrize(
    "page",
    [p for p in PAGES if python_blocks(p.read_text(encoding="utf-8"))],
    ids=lambda p: str(p.relative_to(ROOT)),
)
def test_page_examples_run(page, monkeypatch, tmp_path):
    import matplotlib.pyplot as plt

    # A scratch working folder that sees the repository's data/ and has an empty out/, so the
    # examples' paths work as written and a test run writes nothing into the repository.
    (tmp_path / "data").symlink_to(ROOT / "data", target_is_directory=True)
    (tmp_path / "out").mkdir()
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__docs_example__"}
    rel = page.relative_to(ROOT)
    for line, source in python_blocks(page.read_text(encoding="utf-8")):
        try:
            exec(compile(source, f"{rel}:{line}", "exec"), namespace)
        except Exception as exc:
            raise AssertionError(f"the example at {rel}:{line} failed: {exc!r}") from exc
        finally:
            plt.close("all")

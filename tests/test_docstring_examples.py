"""The ``Example:`` code of the main entry points' docstrings runs.

Each docstring is in Google style (mkdocstrings renders it): its ``Example:`` section holds a
fenced python block, which runs here in a scratch namespace from the repository root (the
examples read ``data/``).
"""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest

import fitting
import lubjax

ROOT = Path(__file__).resolve().parent.parent

ENTRY_POINTS = {
    "lubjax.relax": lubjax.relax,
    "lubjax.make_plan": lubjax.make_plan,
    "lubjax.force_curve": lubjax.force_curve,
    "lubjax.sweep": lubjax.sweep,
    "lubjax.Settings": lubjax.Settings,
    "fitting.fit_traces": fitting.fit_traces,
    "fitting.compare_models": fitting.compare_models,
    "fitting.read_trace": fitting.read_trace,
}

#: The ``Example:`` heading at the docstring's base indentation, then its indented body.
SECTION = re.compile(r"^Example:\n(?P<body>(?:[ \t]+.*\n|\n)+)", re.MULTILINE)
FENCE = re.compile(r"^```python\n(?P<code>.*?)^```", re.MULTILINE | re.DOTALL)
#: The Google-style sections every entry point documents (Settings: Attributes, not Args).
SECTIONS = ("Args:", "Returns:", "Example:")


def example_code(doc: str) -> str:
    """The python code of the ``Example:`` section of a docstring (``inspect.getdoc`` text)."""
    section = SECTION.search(doc + "\n")
    if section is None:
        raise LookupError("no 'Example:' section")
    body = inspect.cleandoc("\n" + section.group("body"))  # drop the section's indentation
    blocks = FENCE.findall(body + "\n")
    if len(blocks) != 1:
        raise LookupError(f"the 'Example:' section holds {len(blocks)} python blocks, not 1")
    return blocks[0]


def test_the_extractor_finds_one_block_and_refuses_none():
    doc = "Summary.\n\nArgs:\n    x: a thing.\n\nExample:\n    Text.\n\n    ```python\n" \
          "    a = 1\n    if a:\n        b = 2\n    ```\n"
    assert example_code(doc) == "a = 1\nif a:\n    b = 2\n"
    with pytest.raises(LookupError):
        example_code("Summary.\n\nArgs:\n    x: a thing.\n")
    with pytest.raises(LookupError):
        example_code("Summary.\n\nExample:\n    just text\n")


@pytest.mark.parametrize("name", ENTRY_POINTS)
def test_docstring_has_the_sections(name):
    doc = inspect.getdoc(ENTRY_POINTS[name])
    wanted = ("Attributes:", "Example:") if name == "lubjax.Settings" else SECTIONS
    for heading in wanted:
        assert re.search(rf"^{heading}$", doc, re.MULTILINE), f"{name}: no {heading!r}"


@pytest.mark.slow  # runs each example as a reader would (up to 16 s each): with --doc-commands
@pytest.mark.doc_command
@pytest.mark.parametrize("name", ENTRY_POINTS)
def test_docstring_example_runs(name, monkeypatch):
    monkeypatch.chdir(ROOT)
    code = example_code(inspect.getdoc(ENTRY_POINTS[name]))
    exec(compile(code, f"<{name} docstring example>", "exec"), {"__name__": "__example__"})

"""docs/gallery.md shows the commands examples/gallery.py runs, and the figures it committed."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "gallery.md"


def _gallery():
    spec = importlib.util.spec_from_file_location("gallery", ROOT / "examples" / "gallery.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _page_commands() -> set[str]:
    """The shell commands of the page's bash blocks, continuation lines joined."""
    text = PAGE.read_text(encoding="utf-8")
    blocks = re.findall(r"^```bash\n(.*?)^```", text, re.MULTILINE | re.DOTALL)
    joined = "\n".join(blocks).replace("\\\n", " ")
    return {" ".join(line.split("#")[0].split()) for line in joined.splitlines()}


def test_the_page_shows_every_command_the_script_runs():
    commands = _page_commands()
    for name, command in _gallery().FIGURES:
        shown = " ".join(command.format(out="figures").split())
        assert shown in commands, f"{name}: {shown!r} is not on docs/gallery.md"


def test_every_figure_on_the_page_is_committed_and_small():
    text = PAGE.read_text(encoding="utf-8")
    images = re.findall(r"!\[[^\]]+\]\((figures/gallery/[^)]+\.png)\)", text)
    assert len(images) >= 8
    for image in images:
        path = ROOT / "docs" / image
        assert path.is_file(), image
        assert path.stat().st_size < 150_000, f"{image}: {path.stat().st_size} bytes"

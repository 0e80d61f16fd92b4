"""mkdocs hooks: serve the figures the examples write, from where they are, drop the Sphinx
roles that docstrings put before their cross-references, and make every figure a link to itself.

The examples' PNGs live in ``examples/out/`` (their scripts write them there); the benchmarks'
figures the pages show are kept in ``docs/figures/`` (benchmark outputs are not committed: a
benchmark re-run that changes a figure is copied there with the page's table). Pages refer to
both as ``figures/<name>.png``.
"""

import re
from pathlib import Path

from mkdocs.structure.files import File

FIGURE_DIRS = ("examples/out",)

#: A Sphinx role before inline code, as the docstrings write cross-references
#: (":func:`relax`"); mkdocstrings renders the code but leaves the role as text.
SPHINX_ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|obj):(?=<code>)")


def on_files(files, config):
    root = Path(config["config_file_path"]).parent
    for folder in FIGURE_DIRS:
        for png in sorted((root / folder).glob("*.png")):
            files.append(
                File.generated(config, f"figures/{png.name}", abs_src_path=str(png))
            )
    return files


#: A figure alone in its paragraph, as Markdown's ``![alt](figures/x.png)`` renders it. Most
#: figures are several panels wide, unreadable at the page's width: the link opens the full size.
FIGURE = re.compile(r'<p>(<img alt="[^"]*" src="(?P<src>[^"]*figures/[^"]+\.png)" />)</p>')


def on_page_content(html, page, config, files):
    html = SPHINX_ROLE.sub("", html)
    return FIGURE.sub(r'<p><a href="\g<src>" title="full size">\1</a></p>', html)

import os

import jax
import pytest

jax.config.update("jax_enable_x64", True)
# The command lines turn on JAX's persistent compilation cache (in ~/.cache/lubjax/jax); tests
# that call them in-process must not write there nor change JAX's configuration for the tests
# after them. The cache's own tests (test_fitting_cache.py) run their CLIs without this.
os.environ["LUBJAX_CACHE"] = "0"


def pytest_addoption(parser):
    parser.addoption(
        "--doc-commands", action="store_true",
        help="also run every documented lubjax / lubjax-fit command and every example of the "
             "docs and docstrings (tests/test_doc_commands.py, test_docs_examples.py, "
             "test_docstring_examples.py; about 5 minutes on two cores); CI runs them after the "
             "suite")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--doc-commands"):
        return
    skip = pytest.mark.skip(reason="a documented command or example: run with --doc-commands "
                                   "(CI does)")
    for item in items:
        if "doc_command" in item.keywords:
            item.add_marker(skip)

import atexit
import os
import shutil
import tempfile

import jax
import pytest

jax.config.update("jax_enable_x64", True)

# One persistent compilation cache for the session, in a fresh folder the xdist workers share:
# the tests compile many identical programs (each test its own closures, each worker its own
# copy), and XLA's executables are keyed by the program, so a hit is the same executable.
# Nothing outside the folder is read or written; the process that made it removes it.
if "LUBJAX_TEST_JAX_CACHE" not in os.environ:
    os.environ["LUBJAX_TEST_JAX_CACHE"] = tempfile.mkdtemp(prefix="lubjax-test-jax-cache-")
    atexit.register(shutil.rmtree, os.environ["LUBJAX_TEST_JAX_CACHE"], True)
jax.config.update("jax_compilation_cache_dir", os.environ["LUBJAX_TEST_JAX_CACHE"])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
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

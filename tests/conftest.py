import os
import subprocess
import sys

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


def pytest_configure(config):
    """Spread the tests over xdist's workers by work stealing, and compile the tests' own
    programs with lubjax's XLA option.

    Work stealing: under ``-n`` without ``--dist``, xdist's "load" scheduling hands each worker
    a long queue up front and never takes it back; the suite's long tests landed in one queue
    (one worker ran 860 s of tests while the other finished after 510 s). "worksteal" lets an
    idle worker take from a busy one's queue.

    The programs the tests jit themselves (jax.jit of a jacfwd, of a loss) compile with the
    XLA option lubjax's own programs take on the CPU (lubjax/_compiler.py: the classic emitters,
    about twice as fast to compile, code as fast). Set in XLA_FLAGS before any backend starts
    (the xdist workers inherit it), and only where this jaxlib knows the flag: XLA aborts on an
    unknown one, so a child process tries it first."""
    if getattr(config.option, "dist", None) == "load" and getattr(
            config.option, "numprocesses", None):
        config.option.dist = "worksteal"
    flag = "--xla_cpu_use_fusion_emitters=false"
    if "xla_cpu_use_fusion_emitters" in os.environ.get("XLA_FLAGS", ""):
        return
    flags = (os.environ.get("XLA_FLAGS", "") + " " + flag).strip()
    probe = subprocess.run(
        [sys.executable, "-c", "import jax; jax.numpy.ones(1).block_until_ready()"],
        env=dict(os.environ, XLA_FLAGS=flags, JAX_PLATFORMS="cpu"), capture_output=True)
    if probe.returncode == 0:
        os.environ["XLA_FLAGS"] = flags


def pytest_collection_modifyitems(config, items):
    """The slow tests first (in their order), then the others: xdist hands out the tests in
    this order, so the suite ends on short tests that fill both workers, not on one worker
    finishing a long test while the other waits (every worker collects the same order)."""
    items.sort(key=lambda item: "slow" not in item.keywords)
    if config.getoption("--doc-commands"):
        return
    skip = pytest.mark.skip(reason="a documented command or example: run with --doc-commands "
                                   "(CI does)")
    for item in items:
        if "doc_command" in item.keywords:
            item.add_marker(skip)

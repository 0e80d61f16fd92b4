"""The persistent compilation cache (lubjax/_compile_cache.py, fitting/_cache.py): only where
asked for, in the folder asked for."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fitting import _cache
from fitting._cache import cache_dir, enable_compilation_cache

from helpers import ROOT, data_path


def _env():
    """A child process's environment with the cache switch as a user has it (conftest.py turns
    it off for the test process)."""
    env = dict(os.environ, PYTHONPATH=ROOT)
    env.pop("LUBJAX_CACHE", None)
    return env


def test_importing_the_library_does_not_enable_the_cache():
    code = "import lubjax, fitting, jax; print(jax.config.jax_compilation_cache_dir)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=_env(), check=True)
    assert out.stdout.strip() == "None"


def test_enable_uses_the_folder_and_the_off_switch(tmp_path, monkeypatch):
    before = jax.config.jax_compilation_cache_dir
    try:
        monkeypatch.setenv("LUBJAX_CACHE", "0")
        assert enable_compilation_cache(str(tmp_path / "off")) is None
        assert not (tmp_path / "off").exists()
        monkeypatch.delenv("LUBJAX_CACHE")
        monkeypatch.setenv("LUBJAX_CACHE_DIR", str(tmp_path / "c"))
        assert cache_dir() == str(tmp_path / "c")
        assert enable_compilation_cache() == str(tmp_path / "c")
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "c")
        monkeypatch.delenv("LUBJAX_CACHE_DIR")
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        assert cache_dir() == str(tmp_path / "xdg" / "lubjax" / "jax")
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


@pytest.mark.slow
def test_a_cli_fit_fills_the_cache_and_no_cache_does_not(tmp_path):
    """Two real CLI runs on a short trace: the first writes
    compiled programs into LUBJAX_CACHE_DIR; --no-cache writes none. (The trace is cut at 4 s.)"""
    import fitting

    tr = fitting.read_trace(data_path("paper_dc154"))
    keep = tr.time < 4.0
    src = tmp_path / "short.csv"
    fitting.write_trace(src, tr._replace(time=tr.time[keep], displacement=tr.displacement[keep],
                                         force=tr.force[keep]))
    env = _env()
    for flag, cache in [((), tmp_path / "on"), (("--no-cache",), tmp_path / "none")]:
        env["LUBJAX_CACHE_DIR"] = str(cache)
        proc = subprocess.run([sys.executable, "-m", "fitting", str(src), "--quiet", "--max-iter",
                               "2", *flag], env=env, capture_output=True, text=True)
        assert proc.returncode in (0, 1), proc.stderr
    assert len(os.listdir(tmp_path / "on")) > 0
    assert len(os.listdir(tmp_path / "on" / "exported")) > 0  # the lowered programs too
    assert not (tmp_path / "none").exists()


@pytest.mark.slow
def test_a_lubjax_run_fills_the_cache_reuses_it_alike_and_no_cache_does_not(tmp_path):
    """`lubjax relax` turns the cache on (as lubjax-fit does): a first run fills the folder, a
    second loads from it and gives the identical result; --no-cache writes nothing."""
    import json

    env = _env()
    args = ["relax", "--beta", "100", "--z0", "0.5", "--t-end", "0.5", "--rtol", "1e-2"]
    forces = []
    for k, (flag, cache) in enumerate([((), "on"), ((), "on"), (("--no-cache",), "none")]):
        env["LUBJAX_CACHE_DIR"] = str(tmp_path / cache)
        out = tmp_path / f"run{k}.json"
        proc = subprocess.run([sys.executable, "-m", "lubjax", *args, "--out", str(out), *flag],
                              env=env, capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
        forces.append(json.loads(out.read_text())["force"])
        if k == 0:
            assert len(os.listdir(tmp_path / "on")) > 0
    assert forces[0] == forces[1] == forces[2]
    assert not (tmp_path / "none").exists()


def test_an_exported_program_is_stored_once_and_reloaded_with_the_same_answer(
        tmp_path, monkeypatch):
    """What a second process sees: the program read back from disk (export is not called
    again), the same values as the plain function, and a new program for a new shape."""

    def f(pair, scale):
        x, y = pair
        return jnp.linalg.solve(x + scale * jnp.eye(x.shape[0]), y), jnp.sum(x)

    fn = jax.jit(f)
    args = ((jnp.asarray(np.random.default_rng(0).random((5, 5))), jnp.ones(5)), jnp.asarray(3.0))
    monkeypatch.setattr(_cache, "_ENABLED", str(tmp_path))
    monkeypatch.setattr(_cache, "_LOADED", {})
    first = _cache.exported("test program", fn)(*args)
    stored = os.listdir(tmp_path / "exported")
    assert len(stored) == 1

    def no_export(*a, **k):
        raise AssertionError("exported again instead of read back")

    monkeypatch.setattr(_cache, "_LOADED", {})
    monkeypatch.setattr(jax.export, "export", no_export)
    again = _cache.exported("test program", fn)(*args)
    for a, b in zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(fn(*args))):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(jax.tree_util.tree_leaves(again), jax.tree_util.tree_leaves(first)):
        np.testing.assert_array_equal(a, b)
    # a new shape is a new program: the failing export falls back to the plain function
    bigger = ((jnp.eye(6), jnp.ones(6)), jnp.asarray(1.0))
    np.testing.assert_array_equal(_cache.exported("test program", fn)(*bigger)[0], 0.5)
    assert os.listdir(tmp_path / "exported") == stored


def test_without_the_cache_exported_is_the_plain_function(monkeypatch):
    monkeypatch.setattr(_cache, "_ENABLED", None)
    calls = []
    assert _cache.exported("x", lambda a: calls.append(a) or a + 1)(1) == 2
    assert calls == [1]

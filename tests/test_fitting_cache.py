"""The persistent compilation cache: only where asked for, in the folder asked for."""

import os
import subprocess
import sys

import jax

from fitting._cache import cache_dir, enable_compilation_cache

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_importing_the_library_does_not_enable_the_cache():
    code = "import lubjax, fitting, jax; print(jax.config.jax_compilation_cache_dir)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=ROOT), check=True)
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


def test_a_cli_fit_fills_the_cache_and_no_cache_does_not(tmp_path):
    """Two real CLI runs on a short trace: the first writes
    compiled programs into LUBJAX_CACHE_DIR; --no-cache writes none. (The trace is cut at 4 s.)"""
    import fitting

    tr = fitting.read_trace(os.path.join(ROOT, "data", "paper_dc154.csv"))
    keep = tr.time < 4.0
    src = tmp_path / "short.csv"
    fitting.write_trace(src, tr._replace(time=tr.time[keep], displacement=tr.displacement[keep],
                                         force=tr.force[keep]))
    env = dict(os.environ, PYTHONPATH=ROOT)
    for flag, cache in [((), tmp_path / "on"), (("--no-cache",), tmp_path / "none")]:
        env["LUBJAX_CACHE_DIR"] = str(cache)
        proc = subprocess.run([sys.executable, "-m", "fitting", str(src), "--quiet", "--max-iter",
                               "2", *flag], env=env, capture_output=True, text=True)
        assert proc.returncode in (0, 1), proc.stderr
    assert len(os.listdir(tmp_path / "on")) > 0
    assert not (tmp_path / "none").exists()

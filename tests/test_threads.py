"""BLAS is held to one thread around the solves, and LUBJAX_BLAS_LIMIT=0 leaves it alone."""

import numpy as np  # noqa: F401  (loads the BLAS whose threads are counted)
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from lubjax._threads import single_threaded_blas


def _blas_threads():
    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


@pytest.fixture(autouse=True)
def two_blas_threads():
    """Two BLAS threads to start from, whatever OMP_NUM_THREADS says, so a limit shows."""
    with threadpool_limits(limits=2, user_api="blas"):
        yield


def test_blas_is_single_threaded_inside_and_restored_after(monkeypatch):
    before = _blas_threads()
    if not before:
        pytest.skip("no BLAS thread pool found in this process")
    assert all(n > 1 for n in before)
    monkeypatch.delenv("LUBJAX_BLAS_LIMIT", raising=False)
    with single_threaded_blas():
        assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before


def test_the_limit_can_be_switched_off(monkeypatch):
    before = _blas_threads()
    if not before:
        pytest.skip("no BLAS thread pool found in this process")
    monkeypatch.setenv("LUBJAX_BLAS_LIMIT", "0")
    with single_threaded_blas():
        assert _blas_threads() == before

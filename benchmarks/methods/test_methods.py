"""Cheap checks of the benchmark methods: the paper-scheme port reproduces docs/model.md's numbers,
and the fully implicit Newton step agrees with lubjax's linearly implicit step on a small case.

They check the benchmarks' own code, so they live beside it (pytest collects them with the
library's tests: ``testpaths`` in pyproject.toml); the library's tests never import benchmarks.
"""

import numpy as np
import pytest

from benchmarks.methods import (
    common,
    explicit_euler,
    lubjax_variant,
    newton,
    paper_scheme,
    picard,
)


def test_paper_influence_constant_pressure_disc():
    # Uniform p̄ = 1 on cells 0..k: w̄(0) = -(8/π²)(π/2) a = -(4/π) a exactly (K(0) = π/2).
    W = paper_scheme.influence_constant(0.1, 4.0)
    k = 10
    a = (k + 0.5) * 0.1
    assert W[0, : k + 1].sum() == pytest.approx(4.0 / np.pi * a, rel=1e-10)


def test_paper_scheme_reproduces_model_numbers():
    # docs/model.md: β=100, z̄0=0.5, Δr̄=0.02, L̄=4, Δt̄=2e-3 gives F̄(1) ≈ 0.906, F̄(5) ≈ 0.780.
    # Same equations at a shorter horizon, eliminated form (identical up to rounding).
    t_out = np.array([0.0, 0.5, 1.0])
    f, info = paper_scheme.run(100.0, 0.5, t_out, dr=0.02, length=4.0, dt=2e-3, reduced=True)
    assert info["ok"]
    assert f[-1] == pytest.approx(0.906, abs=2e-3)


def test_paper_scheme_dense_and_reduced_agree():
    t_out = np.array([0.0, 0.1, 0.2])
    f1, _ = paper_scheme.run(100.0, 0.5, t_out, dr=0.1, length=4.0, dt=1e-2, reduced=True)
    f2, _ = paper_scheme.run(100.0, 0.5, t_out, dr=0.1, length=4.0, dt=1e-2, reduced=False)
    np.testing.assert_allclose(f1, f2, rtol=1e-10, atol=1e-12)


def test_newton_agrees_with_linearly_implicit_lubjax():
    # Same FV mesh, both backward Euler: they differ by O(Δt̄) (lagged vs implicit mobility).
    t_out = np.linspace(0.0, 1.5, 7)
    mesh = dict(mesh="graded", dr=0.05, length=10.0, mesh_growth=1.1)
    f_newton, info = newton.run(100.0, 0.5, t_out, steps="fixed", dt=2.5e-3, **mesh)
    # lubjax's backward Euler under its own error controller (no fixed grid any more).
    f_lub, info_l = lubjax_variant.run(100.0, 0.5, t_out, order=1, rtol=1e-4, **mesh)
    assert info["ok"] and info["converged"] and info_l["ok"]
    assert np.max(np.abs(f_newton - f_lub)) / np.max(f_lub) < 5e-3


def test_picard_mobility_converges_to_newton():
    t_out = np.linspace(0.0, 1.0, 6)
    grid = dict(mesh="graded", dr=0.05, length=10.0, mesh_growth=1.1, steps="fixed", dt=1e-2)
    f_newton, _ = newton.run(100.0, 1.0, t_out, **grid)
    f_pic, info = picard.run(100.0, 1.0, t_out, split="mobility", omega=1.0, tol=1e-11, **grid)
    assert info["converged"]
    np.testing.assert_allclose(f_pic, f_newton, rtol=1e-6, atol=1e-9)


def test_explicit_euler_unstable_at_moderate_step():
    t_out = np.array([0.0, 0.01])
    lim = explicit_euler.stability_limit(100.0, 0.5, mesh="uniform", dr=0.1, length=4.0)
    assert lim < 1e-6
    _, info = explicit_euler.run(100.0, 0.5, t_out, mesh="uniform", dr=0.1, length=4.0,
                                 dt=1e-4)
    assert not info["ok"]


def test_uniform_grid_contains_outputs():
    t = common.uniform_grid(5.0, 1e-1, common.default_t_out(5.0, 0.1))
    assert t.size == 51 and np.allclose(np.diff(t), 0.1)


def test_growing_grid_nodes_and_caps():
    t = common.growing_grid(5.0, 1e-2, 1e-6, 1.1, t_out=[0.5, 2.0])
    assert t[0] == 0.0 and t[-1] == 5.0
    assert np.all(np.isin([0.5, 1.0, 2.0], t)) and np.all(np.diff(t) > 0)
    assert np.max(np.diff(t[t <= 1.0])) <= 1e-2 + 1e-12  # capped in the loading

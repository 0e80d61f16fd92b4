r"""Substrates: how the surface deflects under the film pressure. A scene picks exactly one.

The stepper sees a substrate through its **influence matrix** Ŵ (w̄ = -Ŵ ū for an elastic
"load" ū; :class:`HalfSpace`, eqs 8b, 21, or :class:`Layer`) and its **creep compliance** in
units of 1/E*∞, J(t̄) = J₀ + Σ_k J_k (1 - e^{-t̄/λ_k}), J₀ + Σ J_k = 1 (elastic: J ≡ 1).

By the correspondence principle (constant ν) the elastic load is ū(t̄) = ∫ J(t̄ - s) dp̄(s) =
J₀ p̄ + Σ_k q_k with internal variables

    dq_k/dt̄ = (J_k p̄ - q_k)/λ_k,                                     (V)

and the film is h̄ = z̄ + r̄²/2 + Ŵū. The step integrates (V) by the same BDF formula as the film,
a₀q_kⁿ⁺¹ + a₁q_kⁿ + a₂q_kⁿ⁻¹ = Δt̄ (J_k p̄ⁿ⁺¹ - q_kⁿ⁺¹)/λ_k, which is linear in p̄ⁿ⁺¹:

    ūⁿ⁺¹ = c p̄ⁿ⁺¹ + Σ_k (-a₁q_kⁿ - a₂q_kⁿ⁻¹)/(a₀ + Δt̄/λ_k),
    c = J₀ + Σ_k (Δt̄J_k/λ_k)/(a₀ + Δt̄/λ_k),

so every step is still one linear solve (elastic: c = 1, ū = p̄ exactly). β, p̄, F̄ use the
relaxed modulus E*∞; λ → ∞ is the elastic solver at E*₀ = E*∞/J₀.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import (
    check_finite_array,
    check_layer_base,
    check_poisson,
    check_positive,
    is_traced,
)
from ._influence import influence_matrix
from ._mesh import Mesh
from ._pytree import register


@dataclasses.dataclass(frozen=True)
class HalfSpace:
    """The elastic half-space (the paper's, and the default): w̄ of eq 8b."""

    def influence(self, mesh: Mesh) -> np.ndarray:
        """The influence matrix Ŵ on a mesh: w̄ = -Ŵ ū at the nodes (eqs 8b, 21;
        :func:`lubjax.stepper.influence_matrix`).

        Args:
            mesh: the :class:`lubjax.Mesh`.

        Returns:
            Ŵ, an (N, N) float64 array.
        """
        return influence_matrix(mesh)

    @property
    def elastic(self):
        """The elastic geometry: the substrate itself."""
        return self

    def compliance(self):
        """The creep compliance in the stepper's form: elastic, J ≡ J₀ = 1.

        Returns:
            (J₀, J_k, λ_k) = (1.0, an empty array, an empty array).
        """
        return _ELASTIC

    def step_loads(self, step):
        """The step's elastic load: ūⁿ⁺¹ = p̄ⁿ⁺¹, no memory.

        Args:
            step: the step being taken (``lubjax._stepper.StepRecord``).

        Returns:
            StepLoads: with compliance None (c = 1).
        """
        return _elastic_step_loads(step)


@dataclasses.dataclass(frozen=True)
class Layer:
    """An elastic layer of dimensionless thickness H̄ = H/√(R d_c) on a rigid base, deflecting
    as the half-space times a transfer function C(kH) (docs/model.md, Substrates).

    Args:
        thickness: H̄ = H/√(R d_c), dimensionless, > 0 (``lubjax.layer_thickness_bar(H, R,
            d_c)`` from SI).
        poisson: ν, dimensionless, in (-1, 0.5] (0.5, the default: incompressible, PDMS and
            gels); E* = E/(1 - ν²) as for the half-space, so H̄ → ∞ is the half-space.
        interface: how it rests on the base (``LAYER_BASES``): "bonded" (no slip, the default)
            or "frictionless".

    Raises:
        ValueError: ``thickness`` not > 0, ``poisson`` out of range or an unknown
            ``interface``.
        NotImplementedError: ``thickness`` or ``poisson`` traced (a derivative in them, or
            ``vmap`` over them): the influence matrix is built outside JAX.
    """

    thickness: float
    poisson: float = 0.5
    interface: str = "bonded"

    def __post_init__(self):
        if is_traced(self.thickness) or is_traced(self.poisson):
            raise NotImplementedError(
                "Layer.thickness and Layer.poisson carry no derivative (and cannot be traced): "
                "the layer's influence matrix is built once per mesh, outside JAX. "
                "Differentiate in beta, z0, the drive's numbers or a Viscoelastic substrate's; "
                "for a derivative in the thickness or Poisson's ratio take central differences.")
        thickness = check_positive("Layer.thickness", self.thickness)
        poisson = check_poisson("Layer.poisson", self.poisson)
        check_layer_base("Layer.interface", self.interface)
        object.__setattr__(self, "thickness", thickness)
        object.__setattr__(self, "poisson", poisson)

    def influence(self, mesh: Mesh) -> np.ndarray:
        """The influence matrix Ŵ on a mesh: w̄ = -Ŵ ū at the nodes
        (:func:`lubjax.stepper.layer_influence_matrix`).

        Args:
            mesh: the :class:`lubjax.Mesh`.

        Returns:
            Ŵ, an (N, N) float64 array.
        """
        from ._layer import layer_influence_matrix

        return layer_influence_matrix(mesh, self.thickness, self.poisson, self.interface)

    @property
    def elastic(self):
        """The elastic geometry: the substrate itself."""
        return self

    def compliance(self):
        """The creep compliance in the stepper's form: elastic, J ≡ J₀ = 1.

        Returns:
            (J₀, J_k, λ_k) = (1.0, an empty array, an empty array).
        """
        return _ELASTIC

    def step_loads(self, step):
        """The step's elastic load: ūⁿ⁺¹ = p̄ⁿ⁺¹, no memory.

        Args:
            step: the step being taken (``lubjax._stepper.StepRecord``).

        Returns:
            StepLoads: with compliance None (c = 1).
        """
        return _elastic_step_loads(step)


#: (J₀, J_k, λ_k) of an elastic substrate: the creep compliance in the stepper's form.
_ELASTIC = (1.0, np.zeros(0), np.ones(0))


class StepLoads(NamedTuple):
    """The elastic load ūⁿ⁺¹ of a step as a function of the new pressure p̄ⁿ⁺¹, in the form the
    step's linear system takes it: ūⁿ⁺¹ = c p̄ⁿ⁺¹ + (what the history fixes)."""

    compliance: object  # c; None on an elastic substrate (c = 1, the elastic arithmetic)
    known: jax.Array  # a₀ūⁿ⁺¹ - a₀c p̄ⁿ⁺¹ + a₁ūⁿ + a₂ūⁿ⁻¹ (+ a₃ūⁿ⁻²)
    loads: Callable  # p̄ⁿ⁺¹ ↦ (memory qⁿ⁺¹ (K, N), ūⁿ⁺¹ (N,))


def _history_sum(weights, levels):
    """a₁ x[0] + a₂ x[1] (+ a₃ x[2] where a step can be BDF3), summed in this order."""
    _, a1, a2, a3 = weights
    total = a1 * levels[0] + a2 * levels[1]
    return total if a3 is None else total + a3 * levels[2]


def _elastic_step_loads(step) -> StepLoads:
    """ū = p̄: no memory, and no zero memory terms added (they would change the rounding)."""
    memory = step.history.memory[0]
    return StepLoads(None, _history_sum(step.weights, step.history.elastic_load),
                     lambda p: (memory, p))


@dataclasses.dataclass(frozen=True, eq=False)
class Viscoelastic:
    """A linear viscoelastic substrate: the geometry of ``elastic``, the time dependence of a
    Kelvin-Prony creep compliance (module docstring); from the modulus by
    :meth:`standard_linear_solid` or :meth:`from_prony`. The numbers are pytree leaves.

    Args:
        retardation: J_k, in units of the relaxed compliance 1/E*∞, each ≥ 0: the compliance
            that creeps in with time λ_k (sum < 1; the instantaneous compliance is
            J₀ = 1 - Σ J_k).
        times: λ_k, retardation times (units of t_c), each > 0, as many as ``retardation``.
        elastic: ``HalfSpace()`` (default) or a ``Layer`` (static).

    Raises:
        ValueError: ``retardation`` and ``times`` not 1-D of one length, a J_k < 0 or a sum
            ≥ 1, a λ_k not > 0, or ``elastic`` not a HalfSpace or Layer.
    """

    retardation: tuple | np.ndarray | jax.Array
    times: tuple | np.ndarray | jax.Array
    elastic: HalfSpace | Layer = HalfSpace()

    def __post_init__(self):
        if is_traced(self.retardation) or is_traced(self.times):
            return
        j = np.atleast_1d(np.asarray(self.retardation, np.float64))
        lam = np.atleast_1d(np.asarray(self.times, np.float64))
        if j.ndim != 1 or j.shape != lam.shape or j.size == 0:
            raise ValueError("Viscoelastic needs 1-D retardation and times of the same length")
        if not (np.all(np.isfinite(j)) and np.all(j >= 0) and j.sum() < 1):
            raise ValueError(
                f"Viscoelastic.retardation must be >= 0 with a sum < 1 (J₀ = 1 - sum > 0), got {j}"
            )
        check_finite_array("Viscoelastic.times", lam, 0.0, lo_open=True)
        if not isinstance(self.elastic, (HalfSpace, Layer)):
            raise ValueError("Viscoelastic.elastic must be HalfSpace() or a Layer")
        object.__setattr__(self, "retardation", j)
        object.__setattr__(self, "times", lam)

    @classmethod
    def standard_linear_solid(cls, stiffening, relaxation_time, elastic=None):
        """A standard linear solid, E(t) = E∞ + (E₀ - E∞) e^{-t/τ}: one term, λ = τ E₀/E∞,
        J₁ = 1 - E∞/E₀ (closed form: differentiable in both numbers).

        Args:
            stiffening: E₀/E∞, dimensionless, > 1 (may be traced).
            relaxation_time: τ, the modulus' relaxation time (units of t_c), > 0 (may be
                traced).
            elastic: ``HalfSpace()`` (None, the default) or a ``Layer``.

        Returns:
            Viscoelastic: the substrate.

        Raises:
            ValueError: ``stiffening`` not > 1 or ``relaxation_time`` not > 0.
        """
        m = jnp.asarray(stiffening, jnp.float64) if is_traced(stiffening) else float(stiffening)
        tau = jnp.asarray(relaxation_time, jnp.float64) if is_traced(relaxation_time) else float(
            relaxation_time
        )
        if not is_traced(m) and not (m > 1 and math.isfinite(m)):
            raise ValueError(f"stiffening E0/Einf must be > 1, got {stiffening!r}")
        if not is_traced(tau) and not (tau > 0 and math.isfinite(tau)):
            raise ValueError(f"relaxation_time must be > 0, got {relaxation_time!r}")
        ret = jnp.reshape(1.0 - 1.0 / m, (1,))
        lam = jnp.reshape(tau * m, (1,))
        if not is_traced(m) and not is_traced(tau):
            ret, lam = np.asarray(ret), np.asarray(lam)
        return cls(ret, lam, HalfSpace() if elastic is None else elastic)

    @classmethod
    def from_prony(cls, moduli, times, elastic=None):
        """A relaxation modulus E(t)/E∞ = 1 + Σ_k g_k e^{-t/τ_k} converted exactly to the
        compliance form: rates the roots of s Ē(s), weights its residues (numpy, not traced).

        Args:
            moduli: g_k, dimensionless, each > 0.
            times: τ_k (units of t_c), each > 0 and distinct, as many as ``moduli``.
            elastic: ``HalfSpace()`` (None, the default) or a ``Layer``.

        Returns:
            Viscoelastic: the substrate.

        Raises:
            ValueError: ``moduli`` and ``times`` not 1-D of one length, not finite and > 0,
                repeated times, or a conversion that yields a non-positive term.
        """
        g = np.atleast_1d(np.asarray(moduli, np.float64))
        tau = np.atleast_1d(np.asarray(times, np.float64))
        if g.shape != tau.shape or g.ndim != 1 or g.size == 0:
            raise ValueError("from_prony needs 1-D moduli and times of the same length")
        if not (np.all(g > 0) and np.all(tau > 0) and np.all(np.isfinite(g * tau))):
            raise ValueError(f"Prony moduli and times must be finite and > 0, got {g}, {tau}")
        if np.unique(tau).size != tau.size:
            raise ValueError("Prony times must be distinct")
        order = np.argsort(tau)[::-1]  # poles 1/τ ascending
        g, tau = g[order], tau[order]
        poles = 1.0 / tau
        from scipy.optimize import brentq

        def s_modulus(s):  # s Ē(s)/E∞ = 1 + Σ g s/(s + 1/τ), evaluated at s = -x
            return 1.0 + np.sum(g * (-s) / (-s + poles))

        # One root x of 1 + Σ g (-x)/(1/τ - x) between consecutive poles, the first in (0, 1/τ_1).
        edges = np.concatenate([[0.0], poles])
        rates = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            eps = 1e-14 * hi
            rates.append(brentq(s_modulus, lo + eps if lo > 0 else 0.0, hi - eps, xtol=1e-15,
                                rtol=4 * np.finfo(float).eps, maxiter=500))
        rates = np.asarray(rates)
        # J(t) E∞ = 1 - Σ_k c_k e^{-x_k t}; c_k = -1/(x_k d/dx[s Ē(-x)]) from partial fractions.
        deriv = np.array([np.sum(-g * poles / (poles - x) ** 2) for x in rates])
        c = -1.0 / (rates * deriv)
        j0 = 1.0 - np.sum(c)
        if not (j0 > 0 and np.all(c > 0)):
            raise ValueError("Prony conversion failed (non-positive compliance terms)")
        return cls(c, 1.0 / rates, HalfSpace() if elastic is None else elastic)

    def influence(self, mesh: Mesh) -> np.ndarray:
        """The influence matrix Ŵ of the ``elastic`` geometry (w̄ = -Ŵ ū).

        Args:
            mesh: the :class:`lubjax.Mesh`.

        Returns:
            Ŵ, an (N, N) float64 array.
        """
        return self.elastic.influence(mesh)

    def compliance(self):
        """The creep compliance in the stepper's form, J(t̄) = J₀ + Σ J_k (1 - e^{-t̄/λ_k}).

        Returns:
            tuple: (J₀, J_k, λ_k), J₀ = 1 - Σ J_k and the two arrays, as JAX values.
        """
        ret = jnp.asarray(self.retardation)
        return 1.0 - jnp.sum(ret), ret, jnp.asarray(self.times)

    def step_loads(self, step) -> StepLoads:
        """The step's elastic load: (V) by the step's BDF formula (module docstring).

        Args:
            step: the step being taken (``lubjax._stepper.StepRecord``).

        Returns:
            StepLoads: c = J₀ + Σ_k (Δt̄J_k/λ_k)/(a₀ + Δt̄/λ_k), the known part and
            p̄ⁿ⁺¹ ↦ (qⁿ⁺¹, ūⁿ⁺¹).
        """
        j0, jk, lam = self.compliance()
        a0, dt = step.weights[0], step.dt
        denom = a0 + dt / lam
        creep = dt * jk / lam / denom
        # each sum in this order: its rounding fixes the step sequence
        _, a1, a2, a3 = step.weights
        memory, load = step.history.memory, step.history.elastic_load
        history_memory = -a1 * memory[0] - a2 * memory[1]
        if a3 is not None:
            history_memory = history_memory - a3 * memory[2]
        memory_known = history_memory / denom[:, None]
        known = a0 * jnp.sum(memory_known, axis=0) + a1 * load[0] + a2 * load[1]
        if a3 is not None:
            known = known + a3 * load[2]

        def loads(p):
            memory = memory_known + creep[:, None] * p[None, :]
            return memory, j0 * p + jnp.sum(memory, axis=0)

        return StepLoads(j0 + jnp.sum(creep), known, loads)

    def compliance_at(self, t):
        """The creep compliance.

        Args:
            t: t̄ (units of t_c), ≥ 0; a scalar or an array.

        Returns:
            J(t̄) E*∞ = J₀ + Σ J_k (1 - e^{-t̄/λ_k}), dimensionless, shaped as ``t``.
        """
        j0, jk, lam = self.compliance()
        t = jnp.asarray(t)[..., None]
        return j0 + jnp.sum(jk * (1 - jnp.exp(-t / lam)), axis=-1)


def as_substrate(substrate):
    if substrate is None:
        return HalfSpace()
    if isinstance(substrate, (HalfSpace, Layer, Viscoelastic)):
        return substrate
    raise TypeError(
        "expected a substrate (lubjax.HalfSpace(), Layer(...), Viscoelastic(...)), "
        f"got {type(substrate).__name__}"
    )


register(HalfSpace)
register(Layer, static=("thickness", "poisson", "interface"))
register(Viscoelastic, ("retardation", "times"), static=("elastic",))

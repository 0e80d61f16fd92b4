r"""The optimisers of a fit (``method=``), each on every problem of the fit.

* ``"lm"`` (default): Levenberg–Marquardt on the forward-mode Jacobian J = ∂r/∂x. Step
  (JᵀJ + λ diag JᵀJ) δ = -Jᵀr, accepted when S decreases (then λ ← λ/3, else λ ← 4λ), with
  each |δ_i| ≤ 1 (a factor e per step in E*, η, z0; ≤ ``FLOOR_STEP`` where it lowers the
  viscosity): the least value of the step's quadratic model within those caps
  (:func:`capped_step`). A step whose run makes the film negative or non-finite counts as
  rejected. The Jacobian comes with the residuals at about the cost of one run (the tangents
  reuse the step's factorisation), so every trial evaluates both: one model run per
  iteration. As optimistix writes a solver: a state (:class:`LMState`), :func:`lm_init`,
  :func:`lm_terminate` and :func:`lm_step`, composed by :func:`lm`.
* ``"trf"``: ``scipy.optimize.least_squares`` (trust-region reflective) on the same residuals
  and Jacobian, one problem after another (benchmarks/fit_benchmark.py compares the two). It is
  not in the init/step/terminate shape because scipy runs the loop itself: one call per problem.
* ``"lbfgs"``: ``optax.lbfgs`` on S with reverse-mode ``jax.grad`` (the stepper's checkpointed
  scan), one problem after another, in the same shape: :class:`LBFGSState`,
  :func:`lbfgs_init`, :func:`lbfgs_step` and :func:`lbfgs_terminate`, composed by
  :func:`lbfgs`. Its line search needs a smoother S than LM does: S is smooth in θ only to the
  model's tolerance, so at FIT_SETTINGS' rtol 3e-4 it can stall short of the optimum; a
  tighter rtol (CLI: ``--rtol 1e-5``) converges (docs/accuracy.md, "Optimisers").

Convergence: the Gauss–Newton decrement gᵀ(JᵀJ)⁻¹g with g = Jᵀr, in units of the residual variance
s² = 2S/(n - p), below ``tol`` (1e-4): the remaining step is under 1 % of a standard error. An
error-controlled model is smooth in θ only to its tolerance (the step choices change with θ), so
the cost may stall first: stalled twice with the decrement below ``STALL_DECREMENT``, or no
decreasing step at all (λ > 1e12), or two accepted steps each shorter than ``CREEP_STEP``
standard errors, with the decrement below ``NOISE_DECREMENT``, counts as converged, at the
model's accuracy (the message says which and gives the decrement).

The dry limit (``floors``, LM only: the viscosity): where the film's force is below the noise,
the optimum of η is its bound 0, which the log scale puts at infinity. LM would walk η down
a capped step at a time until the film's force is lost in rounding (tests/test_profile.py: 24
iterations on a stand-in, against 4). Once the Gauss–Newton step lowers η where an e-fold of η
changes χ² by less than ``fitting._profile.FLAT`` s² (the film's force there is under a tenth
of the noise), η is held where it is and the others converge alone; the message says so, and
η's interval comes from the profile of χ² (``fitting._profile``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from lubjax._fitting_api import compiler as _compiler
from lubjax._fitting_api import single_threaded_blas

from . import _model
from ._problem import Evaluator
from ._profile import FLAT

if TYPE_CHECKING:
    import optax

STALL_RTOL = 1e-7
STALL_DECREMENT = 0.05
#: Where not even a short gradient step (λ > 1e12) lowers the cost, the cost is rough on a finer
#: scale than the step the quadratic model predicts: the model's own noise. With the decrement
#: below this the optimum it predicts is within half a standard error (√0.25): converged at the
#: model's accuracy. Seen on one of 100 noise draws (benchmarks/fit_benchmark.py --only batch):
#: stuck at decrement 0.096 (0.3 SE), while compiling the model with other (equally valid)
#: rounding converged 0.2 SE away in 14 iterations.
NOISE_DECREMENT = 0.25
#: An accepted step shorter than this, in standard errors (√(δᵀJᵀJδ/s²)), moves nothing a fit
#: reports. Where LM takes two such steps, its Gauss–Newton steps are rejected and only short,
#: damped ones lower the cost, and by more than the quadratic model's whole step could: the
#: cost is rough on the scale of the step, as where no step lowers it (NOISE_DECREMENT). Seen
#: on the JPK brain creep curve at rtol 1e-3 (tests/test_afm_files.py): steps of 0.003-0.007
#: SE lowered S by 3-44 (s² = 53) where the model predicted 0.03-0.08, from λ = 50 to 10⁴,
#: until the iteration cap.
CREEP_STEP = 0.01
#: The longest step, in e-folds, that lowers the viscosity (step_caps).
FLOOR_STEP = 3.0
METHODS = ("lm", "trf", "lbfgs")
CONVERGED = "converged (Gauss-Newton decrement below tolerance)"


def decrement(r, J, s2):
    """Gauss–Newton decrement gᵀ(JᵀJ)⁻¹g / s²."""
    g = J.T @ r
    try:
        step = np.linalg.lstsq(J.T @ J, g, rcond=None)[0]
    except np.linalg.LinAlgError:
        return math.inf
    return float(g @ step) / max(s2, 1e-300)


class Outcome(NamedTuple):
    x: np.ndarray
    r: np.ndarray
    J: np.ndarray
    iterations: int
    converged: bool
    message: str


# --------------------------------------------------------------------------- Levenberg–Marquardt


@dataclasses.dataclass
class LMState:
    """Levenberg–Marquardt's state, one entry per problem (:func:`lm_init`, :func:`lm_step`)."""

    xs: list  # x of each problem
    current: list  # (r, J, ok) at xs
    cost: np.ndarray  # S = ½|r|² at xs (inf where the run failed)
    lam: np.ndarray  # the damping λ
    done: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray  # the last iteration that proposed a step
    stalled: np.ndarray  # successive trials that did not lower S by STALL_RTOL of it
    creeping: np.ndarray  # accepted steps under CREEP_STEP standard errors since a longer one
    messages: list
    n_samples: list
    floors: list = dataclasses.field(default_factory=list)  # per problem: x indices bounded by 0
    held: list = dataclasses.field(default_factory=list)  # per problem: floors held at the limit

    def free(self, k) -> list[int]:
        """Problem k's x indices still fitted (those not held at the dry limit)."""
        return [i for i in range(self.xs[k].size) if i not in self.held[k]]

    def fitted(self, k, J):
        """J's columns of the parameters still fitted (J itself where none is held: the same
        array keeps JᵀJ's rounding, and with it the iterations of every other fit)."""
        return J[:, self.free(k)] if self.held[k] else J

    def s2(self, k) -> float:
        """Problem k's residual variance s² = 2S/(n - p)."""
        return 2 * self.cost[k] / max(self.n_samples[k] - self.xs[k].size, 1)

    def decrement(self, k) -> float:
        """Problem k's Gauss–Newton decrement at its current point, in the parameters still
        fitted (:func:`decrement`)."""
        r, J, _ = self.current[k]
        return decrement(r, self.fitted(k, J), self.s2(k))


def lm_init(evaluate: Evaluator, x0s, n_samples, floors=None) -> LMState:
    """The state at the starts x0s (one model run); a problem whose run fails there is done.
    ``floors``: per problem, the indices of x whose parameter may stop at its bound 0."""
    K = len(x0s)
    xs = [x.copy() for x in x0s]
    cur = evaluate(xs)
    cost = np.array([0.5 * float(rk @ rk) if ok else np.inf for rk, _, ok in cur])
    state = LMState(xs, cur, cost, np.full(K, 1e-3), np.zeros(K, bool), np.zeros(K, bool),
                    np.zeros(K, int), np.zeros(K, int), np.zeros(K, int), [""] * K, n_samples,
                    [list(f) for f in floors] if floors is not None else [[] for _ in x0s],
                    [[] for _ in x0s])
    for k, (_, _, ok) in enumerate(cur):
        if not ok:
            state.done[k] = True
            state.messages[k] = (
                "the model run at the starting values failed (a negative film, NaN, or a run "
                "that stopped before the trace's end: the step budget ran out or the steps "
                "collapsed)")
    return state


def lm_terminate(state: LMState, tol) -> LMState:
    """Every problem not yet done: hold a parameter that reached its bound (module docstring),
    then converged if the Gauss–Newton decrement of the parameters still fitted is below
    ``tol``."""
    for k in np.flatnonzero(~state.done):
        r, J, _ = state.current[k]
        for j in state.floors[k]:
            if j not in state.held[k] and at_floor(r, J, state.s2(k), j):
                state.held[k].append(j)
        if state.decrement(k) < tol:
            state.done[k], state.converged[k] = True, True
            state.messages[k] = _converged(state, k, CONVERGED)
    return state


def at_floor(r, J, s2, j) -> bool:
    """Whether x_j has reached its bound 0: the Gauss–Newton step lowers it where an e-fold of
    it changes χ² by less than ``FLAT`` s²."""
    A = J.T @ J
    if not A[j, j] < FLAT * s2:
        return False
    return bool(np.linalg.lstsq(A, -(J.T @ r), rcond=None)[0][j] < 0)


def _converged(state: LMState, k, message) -> str:
    """``message``, and where a parameter is held at its bound, that it is."""
    if not state.held[k]:
        return message
    return (f"{message}, at the dry limit: the viscosity is held where the Gauss-Newton step "
            f"kept lowering it and an e-fold of it changes chi2 by under {FLAT:g} of the noise "
            f"variance (the data bound it only from above)")


def step_caps(delta, free, floors) -> np.ndarray:
    """The longest each part |δ_i| of a step may be, in e-folds: 1, or ``FLOOR_STEP`` where δ_i
    lowers a parameter of ``floors`` (x indices; ``free``: the x index of each part of δ).
    Why longer there: lowering the viscosity toward the dry limit flattens the cost, so the
    Gauss–Newton step rarely overshoots; the unit cap made a near-dry fit walk η down an
    e-fold per iteration (data/water_dc140.csv: 10 iterations, 8 with this cap)."""
    return np.array([FLOOR_STEP if free[i] in floors and delta[i] < 0 else 1.0
                     for i in range(len(free))])


def capped_step(M, g, caps_of) -> np.ndarray:
    """The step δ of the damped normal equations M δ = -g held within its caps
    (``caps_of(δ)`` of the unconstrained step): the least value of the quadratic model
    ½δᵀMδ + gᵀδ over the box |δ_i| ≤ cap_i (M is positive definite), by the primal
    active-set method from δ = 0: solve with the held parts fixed; move toward that solution
    until a part meets its cap (then hold it) or take it and release the held part whose
    multiplier points into the box. Within the caps it is the Gauss–Newton step itself.

    Departs from scaling the whole step down to its longest part's cap: near dry η's
    Gauss–Newton step can be many e-folds, and scaling shrank E*'s and z0's steps with it, so
    they crept while η swung an e-fold up and down from one iteration to the next (4 of 50
    near-dry draws under AR(1) noise ran to the iteration cap; docs/accuracy.md)."""
    try:
        delta = -np.linalg.solve(M, g)
    except np.linalg.LinAlgError:
        delta = -g / (np.diag(M) + 1e-300)
        caps = caps_of(delta)
        return np.clip(delta, -caps, caps)
    caps = caps_of(delta)
    if np.all(np.abs(delta) <= caps):
        return delta
    x, held = np.zeros_like(delta), np.zeros(delta.size, bool)
    for _ in range(8 * delta.size):
        free = ~held
        target = x.copy()
        if free.any():
            try:
                target[free] = np.linalg.solve(M[np.ix_(free, free)],
                                               -(g[free] + M[np.ix_(free, held)] @ x[held]))
            except np.linalg.LinAlgError:
                return np.clip(delta, -caps, caps)
        d = target - x
        over = free & (np.abs(target) > caps)
        if over.any():  # move to the first cap met on the way
            reach = (np.sign(d[over]) * caps[over] - x[over]) / d[over]
            first = np.flatnonzero(over)[np.argmin(reach)]
            x = x + np.min(reach) * d
            x[first] = np.sign(d[first]) * caps[first]
            held[first] = True
            continue
        x = target
        pull = np.where(held, np.sign(x) * (M @ x + g), -np.inf)  # > 0: wants into the box
        j = int(np.argmax(pull))
        if pull[j] <= 1e-12 * (np.max(np.abs(g)) + 1e-300):
            break
        held[j] = False
    return x


def _at_model_accuracy(state: LMState, k, dec, most, why) -> bool:
    """Whether problem k, ending for ``why`` (its cost rough on the scale of its steps), has its
    Gauss–Newton decrement ``dec`` below ``most``; if so it is done, converged at the model's
    accuracy."""
    if dec >= most:
        return False
    state.done[k], state.converged[k] = True, True
    state.messages[k] = _converged(
        state, k, f"converged to the model's accuracy ({why}; Gauss-Newton decrement {dec:.2g})")
    return True


def lm_step(evaluate: Evaluator, state: LMState, it: int) -> LMState:
    """Iteration ``it`` of every problem not done: a damped Gauss–Newton step, one model run
    for all of them, each step accepted or rejected; a problem whose cost stalls, or that finds
    no decreasing step, ends here (converged at the model's accuracy or stopped)."""
    xs, cur, cost, lam, done = state.xs, state.current, state.cost, state.lam, state.done
    trial = [x.copy() for x in xs]
    for k in np.flatnonzero(~done):
        r, J, _ = cur[k]
        free, Jf = state.free(k), state.fitted(k, J)
        A = Jf.T @ Jf
        g = Jf.T @ r
        M = A + lam[k] * np.diag(np.diag(A))
        delta = capped_step(M, g, lambda d, k=k, free=free: step_caps(d, free, state.floors[k]))
        trial[k] = xs[k].copy()
        trial[k][free] += delta
        state.iterations[k] = it
    new = evaluate(trial, np.flatnonzero(~done))
    for k in np.flatnonzero(~done):
        r_try, _, ok = new[k]
        cost_try = 0.5 * float(r_try @ r_try) if ok else np.inf
        accept = cost_try < cost[k]
        small = (not accept) or (cost[k] - cost_try < STALL_RTOL * cost[k])
        state.stalled[k] = state.stalled[k] + 1 if small else 0
        if state.stalled[k] >= 2 and _at_model_accuracy(state, k, state.decrement(k),
                                                         STALL_DECREMENT, "cost stalled"):
            continue
        if accept:
            Jd = state.fitted(k, cur[k][1]) @ (trial[k] - xs[k])[state.free(k)]
            short = float(Jd @ Jd) < CREEP_STEP**2 * state.s2(k)
            state.creeping[k] = state.creeping[k] + 1 if short else 0
            xs[k], cur[k], cost[k] = trial[k], new[k], cost_try
            lam[k] = max(lam[k] / 3.0, 1e-9)
            if state.creeping[k] >= 2:
                _at_model_accuracy(state, k, state.decrement(k), NOISE_DECREMENT,
                                   f"steps under {CREEP_STEP:g} standard errors")
        else:
            lam[k] *= 4.0
            if lam[k] > 1e12:
                dec = state.decrement(k)
                if not _at_model_accuracy(state, k, dec, NOISE_DECREMENT, "no decreasing step"):
                    done[k] = True
                    state.messages[k] = (f"stopped: no decreasing step (lambda > 1e12) with "
                                         f"the Gauss-Newton decrement at {dec:.2g}")
    return state


def lm_outcomes(state: LMState, tol, max_iter) -> list[Outcome]:
    """Each problem's :class:`Outcome`; one still running after ``max_iter`` iterations is not
    converged unless its decrement is below ``tol`` after all."""
    out = []
    for k in range(len(state.xs)):
        r, J, _ = state.current[k]
        conv, msg = bool(state.converged[k]), state.messages[k]
        if not state.done[k]:
            msg = f"not converged after {max_iter} iterations"
        if not conv and np.isfinite(r).all() and state.decrement(k) < tol:
            conv, msg = True, _converged(state, k, CONVERGED)
        out.append(Outcome(state.xs[k], r, J, int(state.iterations[k]), conv, msg))
    return out


def lm(evaluate: Evaluator, x0s, n_samples, *, max_iter, tol, progress=None, floors=None):
    """Levenberg–Marquardt for every problem at once (one model run per iteration): init, then
    terminate-or-step until every problem is done or ``max_iter`` is reached (``floors``:
    :func:`lm_init`)."""
    state = lm_init(evaluate, x0s, n_samples, floors)
    for it in range(1, max_iter + 1):
        state = lm_terminate(state, tol)
        if state.done.all():
            break
        state = lm_step(evaluate, state, it)
        if progress is not None:
            progress(it, state.cost, state.done)
    return lm_outcomes(state, tol, max_iter)


# --------------------------------------------------------------------------- scipy


def _single(evaluate: Evaluator, k, x0s):
    """(r, J, ok) of problem k alone at x (the others held at their start)."""
    xs = list(x0s)

    def at(x):
        xs[k] = x
        return evaluate(xs, [k])[k]

    return at


def trf(evaluate, x0s, n_samples, *, max_iter, tol, progress=None):
    """scipy.optimize.least_squares (trust-region reflective) per problem, our Jacobian."""
    from scipy.optimize import least_squares

    out = []
    for k in range(len(x0s)):
        at = _single(evaluate, k, x0s)
        cache = {}

        def fun(x, at=at, cache=cache):
            key = x.tobytes()
            if key not in cache:
                cache.clear()
                r, J, ok = at(x)
                if not ok:  # a failed run: a large residual makes the trust region shrink
                    r, J = np.full_like(r, 1e6), np.zeros_like(J)
                cache[key] = (r, J)
            return cache[key][0]

        def jac(x, fun=fun, cache=cache):
            fun(x)
            return cache[x.tobytes()][1]

        sol = least_squares(fun, x0s[k], jac=jac, method="trf", x_scale="jac",
                            max_nfev=max_iter, ftol=1e-10, xtol=1e-10, gtol=1e-10)
        r, J, ok = at(sol.x)
        s2 = float(r @ r) / max(n_samples[k] - sol.x.size, 1)
        dec = decrement(r, J, s2) if ok else math.inf
        conv = ok and dec < STALL_DECREMENT
        msg = f"scipy least_squares: {sol.message} (Gauss-Newton decrement {dec:.2g})"
        out.append(Outcome(sol.x, r, J, int(sol.nfev), conv, msg))
        if progress is not None:
            progress(sol.nfev, np.array([sol.cost]), np.array([True]))
    return out


class LBFGSProblem(NamedTuple):
    """Problem k alone for L-BFGS: its compiled iteration and its model run."""

    iterate: Callable  # (x, opt_state) -> (x, opt_state, S at the old x)
    run: Callable  # x -> (r, J, ok), the other problems held at their start
    n_samples: int


class LBFGSState(NamedTuple):
    """L-BFGS's state for one problem (:func:`lbfgs_init`, :func:`lbfgs_step`)."""

    x: jax.Array
    opt_state: optax.OptState
    iterations: int
    done: bool
    converged: bool
    message: str


def lbfgs_problem(evaluate: Evaluator, k, x0s, n_samples) -> LBFGSProblem:
    """Problem k's loss S = ½|r|² (infinite where the film goes negative) and one compiled
    ``optax.lbfgs`` iteration on it, gradient by reverse mode."""
    import optax

    spec, solver, lay = evaluate.spec, evaluate.solver, evaluate.layout
    members = evaluate.groups[k]
    datas = [jax.tree_util.tree_map(lambda a, t=t: a[t], evaluate.data) for t in members]
    base = [jnp.asarray(lay.base[t]) for t in members]
    Ms = [jnp.asarray(lay.M[t]) for t in members]

    def loss(x):
        total = 0.0
        for d, b, m in zip(datas, base, Ms):
            y, film = _model.predict(b + m @ x, d, solver, spec)
            r = d.weight * (y - d.response) / d.noise
            total = total + jnp.where(film > 0, 0.5 * jnp.sum(r**2), jnp.inf)
        return total

    opt = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(loss)

    @_compiler.jit
    def iterate(x, opt_state):
        value, grad = value_and_grad(x, state=opt_state)
        updates, opt_state = opt.update(grad, opt_state, x, value=value, grad=grad,
                                        value_fn=loss)
        return optax.apply_updates(x, updates), opt_state, value

    return LBFGSProblem(iterate, _single(evaluate, k, x0s), n_samples[k])


def lbfgs_init(x0, max_iter) -> LBFGSState:
    """The state at the start x0 (no model run)."""
    import optax

    x = jnp.asarray(x0)
    return LBFGSState(x, optax.lbfgs().init(x), 0, False, False,
                      f"not converged after {max_iter} iterations (L-BFGS's line search "
                      "stalls where the error-controlled model is not smooth: a tighter "
                      "tolerance, settings with rtol=1e-5 or the CLI's --rtol 1e-5, or method "
                      "'lm')")


def lbfgs_step(problem: LBFGSProblem, state: LBFGSState, progress=None) -> LBFGSState:
    """One L-BFGS iteration (gradient and line search); a non-finite loss ends the problem."""
    with single_threaded_blas():
        x, opt_state, value = problem.iterate(state.x, state.opt_state)
    it = state.iterations + 1
    if progress is not None:
        progress(it, np.array([float(value)]), np.array([False]))
    state = state._replace(x=x, opt_state=opt_state, iterations=it)
    if not math.isfinite(float(value)):
        state = state._replace(done=True,
                               message="stopped: non-finite loss (negative film or NaN)")
    return state


def lbfgs_terminate(problem: LBFGSProblem, state: LBFGSState) -> LBFGSState:
    """Every fifth iteration (a model run with its Jacobian), converged where the Gauss–Newton
    decrement is below ``STALL_DECREMENT``."""
    if state.done or state.iterations % 5:
        return state
    r, J, ok = problem.run(np.asarray(state.x))
    s2 = float(r @ r) / max(problem.n_samples - state.x.size, 1)
    if ok and decrement(r, J, s2) < STALL_DECREMENT:
        state = state._replace(done=True, converged=True,
                               message=CONVERGED)
    return state


def lbfgs(evaluate, x0s, n_samples, *, max_iter, tol, progress=None):
    """optax L-BFGS per problem on S = ½|r|²: init, then step-and-terminate until done or
    ``max_iter`` is reached."""
    out = []
    for k in range(len(evaluate.groups)):
        problem = lbfgs_problem(evaluate, k, x0s, n_samples)
        state = lbfgs_init(x0s[k], max_iter)
        while not state.done and state.iterations < max_iter:
            state = lbfgs_terminate(problem, lbfgs_step(problem, state, progress))
        r, J, _ = problem.run(np.asarray(state.x))
        out.append(Outcome(np.asarray(state.x), r, J, state.iterations, state.converged,
                           state.message))
    return out


OPTIMISERS = {"lm": lm, "trf": trf, "lbfgs": lbfgs}

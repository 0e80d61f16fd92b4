"""Sweeps (mapped or vmap-ped) agree with single runs; sharding over several (forced host)
devices works."""

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import lubjax

COARSE = lubjax.Settings(dr=0.05, mesh_growth=1.1, length=50.0, error_estimate=False,
                         contact_radius=None)  # sweep uses the plain mesh: compare like with like


@pytest.mark.parametrize("batching", ["map", "vmap"])
def test_sweep_matches_single_runs(batching):
    res = lubjax.sweep([30.0, 300.0, 30.0], [0.6, 0.6, 1.5], t_end=2.0, settings=COARSE,
                       batching=batching)
    assert res.force.shape == (3, res.t.size) and res.ok.all()
    for k in range(3):
        single = lubjax.relax(res.beta[k], res.z0[k], t_end=2.0, settings=COARSE)
        # Batched and single solves round differently; an error ratio at 1 could flip one
        # accept/reject decision, so the step counts are asked to agree to two steps.
        assert abs(int(res.steps[k]) - single.accepted) <= 2
        # Measured (β = 300 and 30, z̄0 = 0.6 and 1.5): the same accepted and rejected counts,
        # but the step times part at the 10th step (1e-9 relative, t̄ ~ 1e-7): there F̄ is still
        # ~1e-12, its error estimate is rounding, and the step sizes it sets differ by rounding.
        # The sequences then stay apart continuously, and the runs differ by a fraction of the
        # controlled local error (2e-7 of the peak at rtol 1e-4), not to the last bit.
        peak = single.force.max()
        assert np.max(np.abs(res.force[k] - single.at(res.t))) < 0.05 * COARSE.rtol * peak


def test_sweep_rejects_bad_values():
    with pytest.raises(ValueError, match="beta"):
        lubjax.sweep([1.0, -2.0], 0.5)
    with pytest.raises(ValueError, match="devices"):
        lubjax.sweep([1.0], 0.5, devices=99)
    with pytest.raises(ValueError, match="batching must be one of"):
        lubjax.sweep([1.0], 0.5, batching="pmap")
    # traced pairs (a derivative, jit, vmap): the message names the transformable batch
    for transform in (jax.grad, jax.jit):
        with pytest.raises(TypeError, match="force_curve"):
            transform(lambda b: lubjax.sweep(b, 0.5).force.sum())(100.0)


def test_sweep_shards_across_two_host_devices():
    code = textwrap.dedent(
        """
        import numpy as np, jax, lubjax
        assert len(jax.devices()) == 2
        s = lubjax.Settings(dr=0.05, mesh_growth=1.1, length=50.0, error_estimate=False)
        b = np.array([20.0, 200.0, 2000.0])  # odd size: padded to 4
        two = lubjax.sweep(b, 0.8, t_end=1.5, settings=s)
        one = lubjax.sweep(b, 0.8, t_end=1.5, settings=s, devices=1)
        assert two.devices == 2 and two.force.shape == one.force.shape
        assert np.allclose(two.force, one.force, rtol=1e-8, atol=1e-14)
        print("ok")
        """
    )
    # PJRT_NPROC=3: one intra-op thread more than device programs, else jaxlib's batched LAPACK
    # deadlocks the host pool (lubjax/_sharding.py).
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", PJRT_NPROC="3")
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip().endswith("ok")

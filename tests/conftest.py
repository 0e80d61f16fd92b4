import os

import jax

jax.config.update("jax_enable_x64", True)
# The command lines turn on JAX's persistent compilation cache (in ~/.cache/lubjax/jax); tests
# that call them in-process must not write there nor change JAX's configuration for the tests
# after them. The cache's own tests (test_fitting_cache.py) run their CLIs without this.
os.environ["LUBJAX_CACHE"] = "0"

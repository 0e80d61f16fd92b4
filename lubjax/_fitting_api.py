"""What ``fitting`` (``lubjax-fit``) takes from lubjax beyond the public surface (``lubjax.*``,
``lubjax.stepper.*``): the one internal module it may import. Everything here is machinery
the fits share with ``relax``, ``sweep`` and the ``lubjax`` command rather than physics:

* ``checks``: validation of numbers, ranges and choices, with the solver's wording
  (lubjax/_checks.py);
* ``compiler``: how programs are compiled (XLA options) and cached (lubjax/_compiler.py);
* ``sharding``: batches over devices, mapped or vmap-ed per device (lubjax/_sharding.py);
* ``compile_cache``: JAX's persistent compilation cache and its folder
  (lubjax/_compile_cache.py);
* ``cli_options``: the command-line options both commands share (accuracy, substrate, cache,
  debug) and their checks (lubjax/_cli_options.py);
* ``files``: the commands' exit codes, argument parser, output checks and atomic writes
  (lubjax/_files.py); :class:`UsageError`, the one a command's checks raise, by name;
* ``estimate``: Richardson's estimate and the scheme's observed orders, which the fits' solver
  error shares with ``relax``'s (lubjax/_estimate.py);
* :func:`single_threaded_blas`: the solver's runs keep BLAS to one thread (lubjax/_threads.py);
* :func:`motion_start`: the last sample at rest before a recorded motion, the breakpoint rule
  of a sampled travel (lubjax/_indenter.py).
"""

from . import _checks as checks
from . import _cli_options as cli_options
from . import _compile_cache as compile_cache
from . import _compiler as compiler
from . import _estimate as estimate
from . import _files as files
from . import _sharding as sharding
from ._files import UsageError
from ._indenter import motion_start
from ._threads import single_threaded_blas

__all__ = [
    "UsageError", "checks", "cli_options", "compile_cache", "compiler", "estimate", "files",
    "motion_start", "sharding", "single_threaded_blas",
]

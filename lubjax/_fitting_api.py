"""What ``fitting`` (``lubjax-fit``) takes from lubjax beyond the public surface (``lubjax.*``,
``lubjax.stepper.*``): the one internal module it may import, machinery the fits share with
``relax``, ``sweep`` and the ``lubjax`` command rather than physics (each name is the module
of the same name: validation, compilation, sharding, the compilation cache, the shared CLI
options, files and exit codes, Richardson's estimate, single-threaded BLAS, and the breakpoint
rule of a sampled travel).
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

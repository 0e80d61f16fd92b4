"""``python -m fitting TRACE.csv ...``: same as ``lubjax-fit``."""

import sys

from ._cli import main

sys.exit(main())

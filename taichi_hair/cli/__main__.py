"""``python -m taichi_hair.cli ...``: the ``taichi-hair`` command."""

import sys

from .main import main

sys.exit(main())

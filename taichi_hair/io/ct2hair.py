"""CT2Hair ``.bin`` (read only): the USC ``.data`` layout with 7 float32 per point.

Each point is x, y, z followed by 4 extra values (stride 28 bytes).  The extra
values are dropped (only x, y, z are kept); the units are not stated by the
format, so ``units`` is left unknown.  Strands with fewer than 2 points are
skipped with a warning, as for ``.data``.
"""

from __future__ import annotations

from ._util import read_bytes
from .groom import Groom
from .usc import groom_from_walk, walk_strands

FLOATS_PER_POINT = 7


def read_ct2hair(path) -> Groom:
    pts, counts = walk_strands(read_bytes(path), path, FLOATS_PER_POINT)
    return groom_from_walk(path, pts, counts, params={"ct2hair_extra_values_per_point": 4})

"""What a job of the objects stage needs, a leaf module: the config validator (:mod:`tohgs.config`) checks
``resources.rules.prepare_object.mem_mb`` against ``objects.limits.max_faces`` with it, and importing it does
not bring the objects stage's code into the code inputs of every job that validates its settings."""

from __future__ import annotations

import math

#: Peak memory of one ``prepare_object`` job (``/usr/bin/time -v``, default settings, CoACD on the whole
#: mesh) on watertight tori of 20k, 100k and 200k faces: 325, 768 and 1302 MB, a line of 220 MB plus 5.4 MB
#: per 1000 faces (the repair's adjacency caches and CoACD's input grow with the faces).
PREPARE_BASE_MB = 220.0
PREPARE_MB_PER_1000_FACES = 5.4
#: Headroom over the measured line for other shapes and settings.
PREPARE_MEMORY_MARGIN = 1.25


def prepare_memory_mb(max_faces: int) -> int:
    """The memory, MB, a ``prepare_object`` job may need for a mesh of ``max_faces`` faces (the measured line
    times :data:`PREPARE_MEMORY_MARGIN`): what ``resources.rules.prepare_object.mem_mb`` must cover for the
    limit ``objects.limits.max_faces`` (100,000 faces: 950 MB, within the default 1000)."""
    return int(math.ceil(PREPARE_MEMORY_MARGIN * (PREPARE_BASE_MB + PREPARE_MB_PER_1000_FACES * max_faces / 1000)))

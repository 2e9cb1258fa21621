"""Run native-code work (PyBullet) in a child process, so that a crash becomes a clear Python error.

PyBullet is C++ and can die with a signal (its vhacd segfaults in pybullet 3.2.7). Run in-process, such a
crash would kill the job with a bare "Segmentation fault"; here the parent sees the child die and raises
:class:`SimulationCrash` with a message that names what was being done (task, object, seed). The child
enables :mod:`faulthandler`, so the native stack goes to the job's log too.
"""

from __future__ import annotations

import faulthandler
import multiprocessing as mp
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any


class SimulationCrash(RuntimeError):
    """The simulator process died (a native crash); the message names what it was doing."""


def _call(fn: Callable[..., Any], kwargs: dict[str, Any]) -> Any:
    faulthandler.enable()
    return fn(**kwargs)


def run_isolated(fn: Callable[..., Any], kwargs: dict[str, Any], what: str) -> Any:
    """Call ``fn(**kwargs)`` in a fresh child process and return its result.

    Args:
        fn: a picklable (module-level) function.
        kwargs: its keyword arguments (picklable).
        what: a description for the error message, e.g. ``"placing scenes for object 'pb-duck', seed 0"``.

    Raises:
        SimulationCrash: the child died without returning (segfault, abort, killed).
        Exception: whatever ``fn`` raised, re-raised as is.
    """
    # fork, not spawn: spawn re-runs the parent's __main__ (a Snakemake script) in the child.
    with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("fork")) as pool:
        future = pool.submit(_call, fn, kwargs)
        try:
            return future.result()
        except BrokenProcessPool as exc:
            raise SimulationCrash(f"the simulator crashed (its process died) while generating {what}; "
                                  "see the log for the native stack") from exc

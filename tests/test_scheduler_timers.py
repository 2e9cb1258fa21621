"""Snakemake's re-scheduling timers coalesced (tohgs.scheduler_timers)."""
import threading
import time
from types import SimpleNamespace

from tohgs import scheduler_timers
from tohgs.scheduler_timers import _schedule_reevaluation_once, coalesce_scheduler_timers


def _wakeups(sem: threading.Semaphore, wait: float) -> int:
    """How many releases the semaphore collects within ``wait`` seconds."""
    n, end = 0, time.monotonic() + wait
    while sem.acquire(timeout=max(0.0, end - time.monotonic())):
        n += 1
    return n


def test_requests_while_a_wakeup_is_pending_share_it():
    scheduler = SimpleNamespace(_open_jobs=threading.Semaphore(0))
    for _ in range(20):  # 20 passes ask for a pass 0.1 s later: one wake-up
        _schedule_reevaluation_once(scheduler, 0.1)
    assert scheduler._tohgs_wakeup.daemon  # a pending wake-up does not hold the process at exit
    assert _wakeups(scheduler._open_jobs, 1.5) == 1
    _schedule_reevaluation_once(scheduler, 0.05)  # after it fired, the next request gets its own
    assert _wakeups(scheduler._open_jobs, 1.5) == 1


def test_snakemakes_own_timers_pile_up_and_the_workflow_replaces_them():
    assert coalesce_scheduler_timers()
    from snakemake.scheduling.job_scheduler import JobScheduler

    assert JobScheduler._schedule_reevalutation is _schedule_reevaluation_once
    assert coalesce_scheduler_timers()  # twice is the same
    assert scheduler_timers.ORIGINAL is not None and scheduler_timers.ORIGINAL is not _schedule_reevaluation_once
    # what it fixes: Snakemake's method starts a timer per request, each a wake-up (a pass, and the next timer)
    scheduler = SimpleNamespace(_open_jobs=threading.Semaphore(0))
    for _ in range(5):
        scheduler_timers.ORIGINAL(scheduler, 0.05)
    assert _wakeups(scheduler._open_jobs, 1.5) == 5

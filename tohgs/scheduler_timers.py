"""One pending re-scheduling timer in Snakemake's job scheduler instead of one per job event.

While a job rate limit is set (Snakemake's ``--max-jobs-per-timespan``, whose CLI default ``100/1s`` is
always set), the scheduler ends every scheduling pass that found ready jobs by starting a
``threading.Timer`` that wakes it again one timespan later (``JobScheduler._schedule_reevalutation`` in
Snakemake 9). The wake-ups count on a semaphore, so each pass's timer starts the next pass, which starts
another timer: a chain that never ends while jobs wait for cores, and every job event (a job finished,
a checkpoint) starts one more chain. After E events the scheduler runs about E passes per timespan, each
re-evaluating the params and statting the inputs of every ready job. On the default run (570 jobs on 2
cores) the Snakemake process used 42 % of a core 83 minutes in, taken from the jobs (docs/history.md).
The timers are also non-daemon threads, so the process waits for the last of them before it exits.

:func:`coalesce_scheduler_timers` replaces that method with one that starts a timer only when none is
pending, as a daemon thread: the scheduler still wakes one timespan after a pass (the rate limit's
purpose: to submit what the limit held back) and on every job event, but the chains no longer pile up, and
the process exits as soon as its jobs are done. Nothing else of the scheduler changes.
"""

from __future__ import annotations

import logging
import threading

log = logging.getLogger(__name__)

_LOCK = threading.Lock()
#: Snakemake's own method, kept when :func:`coalesce_scheduler_timers` replaced it.
ORIGINAL = None


def _schedule_reevaluation_once(self, delay: float) -> None:
    """Release the scheduler's semaphore ``delay`` seconds from now, unless a release is already pending
    (then that pending wake-up serves this request too). The pending mark is cleared before the release,
    so the pass that a wake-up starts can always ask for the next one."""

    def wake() -> None:
        with _LOCK:
            self._tohgs_wakeup = None
        self._open_jobs.release()

    with _LOCK:
        if getattr(self, "_tohgs_wakeup", None) is not None:
            return
        timer = threading.Timer(delay, wake)
        timer.daemon = True
        self._tohgs_wakeup = timer
    timer.start()


def coalesce_scheduler_timers() -> bool:
    """Install :func:`_schedule_reevaluation_once` as Snakemake's ``JobScheduler._schedule_reevalutation``
    (module docstring). Returns whether it was installed: False where Snakemake's scheduler has no such
    method (another Snakemake version), which is left as it is."""
    try:
        from snakemake.scheduling.job_scheduler import JobScheduler
    except ImportError:
        log.debug("no snakemake.scheduling.job_scheduler here: the scheduler's timers are left as they are")
        return False
    if not callable(getattr(JobScheduler, "_schedule_reevalutation", None)):
        log.debug("JobScheduler has no _schedule_reevalutation: the scheduler's timers are left as they are")
        return False
    global ORIGINAL
    if JobScheduler._schedule_reevalutation is not _schedule_reevaluation_once:
        ORIGINAL = JobScheduler._schedule_reevalutation
        JobScheduler._schedule_reevalutation = _schedule_reevaluation_once
    return True

"""benchmarks/job_times.py reads a Snakemake log: each job's start, finish and threads, and the idle cores."""

from helpers import load_benchmark

job_times = load_benchmark("job_times")

# Two runs appended (job ids restart), a job that never finishes, threads 2 on one job: Snakemake 9's layout.
LOG = """\
Building DAG of jobs...
[Sat Dec  5 17:00:00 2026]
localrule prepare_object:
    output: results/objects/a
    jobid: 1
    wildcards: object=a
    priority: 30
Shell command: None

[Sat Dec  5 17:00:00 2026]
rule train:
    jobid: 2
    threads: 2
    resources: tmpdir=/tmp
[Sat Dec  5 17:01:00 2026]
Finished jobid: 1 (Rule: prepare_object)
1 of 3 steps (33%) done
[Sat Dec  5 17:03:00 2026]
Finished jobid: 2 (Rule: train)
[Sat Dec  5 17:03:00 2026]
rule evaluate:
    jobid: 1
[Sat Dec  5 17:04:00 2026]
Finished jobid: 1 (Rule: evaluate)
[Sat Dec  5 17:04:00 2026]
rule table:
    jobid: 3
"""

def test_log_jobs_pairs_each_finish_with_the_latest_job_of_its_id(tmp_path):
    log = tmp_path / "run.log"
    log.write_text(LOG)
    jobs = job_times.log_jobs(log)
    assert [(j["rule"], j["threads"]) for j in jobs] == [("prepare_object", 1), ("train", 2), ("evaluate", 1)]
    assert [(j["end"] - j["start"]).total_seconds() for j in jobs] == [60, 180, 60]


def test_core_use_counts_held_and_idle_core_minutes(tmp_path):
    log = tmp_path / "run.log"
    log.write_text(LOG)
    use = job_times.core_use(job_times.log_jobs(log), cores=2)
    # 4 minutes: minute 0 held by both jobs (3 cores asked, 2 counted), minutes 1-2 by train (2), minute 3 by
    # evaluate alone (1 idle)
    assert use["span_minutes"] == 4.0 and use["jobs"] == 3
    assert use["core_minutes_held"] == 1 + 6 + 1
    assert use["core_minutes_idle"] == 1.0

"""Snakemake script of rule predict: grasps for every test configuration of a task with one method."""
from pathlib import Path

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.methods.predict import predict  # noqa: E402

inp, p = snakemake.input, snakemake.params
out = Path(snakemake.output[0])
predict(snakemake.wildcards.task, out.stem, p.method, inp.shards, {Path(m).stem: m for m in inp.models},
        {**p.settings, "threads": snakemake.threads}, out, hand=inp.hand, base=inp.base[0] if inp.base else None,
        complete=True)

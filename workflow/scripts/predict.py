"""Snakemake script of rule predict: grasps for every test configuration of a task with one method."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.models.predict import predict  # noqa: E402

w, inp, p = snakemake.wildcards, snakemake.input, snakemake.params
predict(w.task, w.method, inp.shards, inp.grasp_model, p.contact_source, {**p.settings, "threads": snakemake.threads},
        snakemake.output[0], contact_ckpt=inp.contact_model[0] if inp.contact_model else None)

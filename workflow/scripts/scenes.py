"""Snakemake script of rule scenes: the configurations of one task and target object."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.assets.sources import accepted_objects, task_set  # noqa: E402
from tohgs.sim.scenes import make_scene_store  # noqa: E402

task = snakemake.wildcards.task
pool = accepted_objects(snakemake.input.objects, task_set(task))  # obstacles / base bricks to draw from
make_scene_store(task, snakemake.wildcards.object, pool, snakemake.params.objects_dir,
                 f"{snakemake.input.supports}/supports.json", snakemake.params.settings, snakemake.params.seed,
                 snakemake.output[0])

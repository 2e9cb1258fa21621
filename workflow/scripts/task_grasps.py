"""Snakemake script of rule task_grasps: expand one object's prior grasps over its task configurations."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.grasps.expand import make_task_grasps  # noqa: E402
from tohgs.hand import HandAssets  # noqa: E402

inp = snakemake.input
make_task_grasps(inp.scenes, inp.prior, snakemake.params.objects_dir, f"{inp.supports}/supports.json",
                 HandAssets.load(inp.hand), snakemake.params.settings, snakemake.output[0])

"""Snakemake script of rule prepare_object: one object through the objects stage."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.assets.objects import prepare_object  # noqa: E402

size = dict(snakemake.params.size)
prepare_object(
    spec=snakemake.params.spec,
    out_dir=snakemake.output[0],
    size=size,
    brick_scale=size.get("brick_scale", 1.0),
    decomposition=snakemake.params.decomposition,
    density=snakemake.params.density,
    seed=size.get("seed", 0),
    cache_dir=snakemake.params.cache_dir,
    limits=snakemake.params.limits,
)

"""Snakemake script of rule prior_synthesis: optimise and measure the prior grasps of one object."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.grasps.prior import make_prior_grasps  # noqa: E402
from tohgs.hand import HandAssets, HandModel  # noqa: E402

p = snakemake.params
make_prior_grasps(snakemake.input.object, HandModel(HandAssets.load(snakemake.input.hand)), p.hand_model, p.synthesis,
                  p.sdf, p.sd, p.voxel_pitch, p.plane_direction, p.seed, snakemake.output[0], p.cache_dir,
                  snakemake.threads, screen=p.screen)

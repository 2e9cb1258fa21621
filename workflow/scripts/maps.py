"""Snakemake script of rule maps: one shard of distance and contact maps of a task and split."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.data.build_maps import make_map_shard  # noqa: E402
from tohgs.hand import HandAssets  # noqa: E402

w, inp, p = snakemake.wildcards, snakemake.input, snakemake.params
make_map_shard(w.task, w.split, int(w.shard), p.n_shards, inp.scenes, inp.grasps, snakemake.params.objects_dir,
               f"{inp.supports}/supports.json",
               HandAssets.load(inp.hand), p.settings, p.test_configs, p.seed, snakemake.output[0])

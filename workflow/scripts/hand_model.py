"""Snakemake script of rule hand_model: the configured hand backend as MANO-layout arrays."""
from pathlib import Path

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import load_hand_assets  # noqa: E402

assets = load_hand_assets(snakemake.params.model, snakemake.params.mano_path,
                          Path(snakemake.params.cache_dir) / "hand")
assets.save(snakemake.output[0])

"""The Zarr stores of tohgs: schemas, writers and validating readers."""

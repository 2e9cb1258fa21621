"""Geometry: signed distances, sampling, inside tests, transforms."""

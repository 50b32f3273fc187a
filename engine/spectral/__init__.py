"""Spectral bands: the band model, band-averaged properties and the shipped tables."""

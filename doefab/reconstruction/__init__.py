"""Reconstruction: the feature-space Wiener deconvolution (DWDN) and the conditional networks."""

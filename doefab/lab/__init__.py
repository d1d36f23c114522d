"""After the fab: a fabricated part's own recordings read, calibrated into a PSF pair and the sensor's crosstalk,
the part diagnosed against the tolerance model, and a user's captures reconstructed into files other programs open."""

"""
Use a measured PSF
==================

The shipped networks were trained with the PSFs of the design as drawn. The part you hold differs: its etch
depths are off by a few percent, and its masks landed a little apart. The networks take the PSF pair as an
input at every call, so a PSF **measured** on your camera can replace the simulated one without retraining.

This tutorial makes such a part (the committed streak design etched 15 % too shallow, with its two deepest
masks misaligned by a few micrometres), records its PSFs as a lab would (a point source, one aperture half blocked at a time, dark
frames, noise), turns the recordings into a PSF pair, and reconstructs the part's captures with the nominal
and with the measured pair.
"""

# %%
# The part that was made
# ----------------------
# The shipped HDR networks belong to the committed streak design (``masks/streak/design`` in a clone of the
# repository). Its camera is the HDR preset: a 3200² DOE grid at 2.7 µm.
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from skimage import data, transform

import doefab

rec = doefab.load_reconstructor("hdr")
design = doefab.Design.load(Path(doefab.__file__).resolve().parents[1] / "masks" / "streak" / "design")
camera, nominal = design.camera, rec.pair
kernel = nominal.coded.shape[-1]
part = doefab.fabricated_height(design.levels, camera, camera.design_wavelength, depth_scale=(0.85,) * 4,
                                overlay=((0, 0), (0, 0), (2e-6, 0), (4e-6, -2e-6)), supersample=1)
true_pair = doefab.split_aperture_psf(part, camera, nominal.wavelengths, nominal.depths, kernel_size=kernel)
print(f"DOE grid {camera.doe_pixels}² at {camera.doe_pitch * 1e6:g} µm; PSF window {kernel} sensor pixels")

# %%
# Record its PSFs
# ---------------
# A point source at the focus distance, the sensor's raw colour channels, the plain half blocked for the coded
# PSF and the DOE half blocked for the plain one; each recording is the mean of many frames, less a dark frame.
# The simulation stands in for the lab here: photons, read noise and a dark offset in digital numbers (DN).
rng = np.random.default_rng(1)
photons, read_noise, dark = 4.0e6, 3.0, 100.0  # photons in a half's window per colour, e⁻ rms, DN


def record(psf):
    """A dark-subtracted, frame-averaged recording (DN) of a [3, K, K] PSF."""
    expected = psf.numpy() / psf.numpy().sum(axis=(-2, -1), keepdims=True) * photons
    frames = rng.poisson(expected) + rng.normal(dark, read_noise, expected.shape)
    return frames - dark  # the dark frame's mean is subtracted


raw_coded, raw_plain = record(true_pair.coded[0]), record(true_pair.uncoded[0])

# %%
# Turn the recordings into a PSF pair
# -----------------------------------
# A PSF pair holds fractions of the whole aperture's light per sensor pixel (``[depths, wavelengths, K, K]``),
# so each recording is clipped at zero and scaled to the share of the light its half puts in the window (the
# simulated pair gives that share; a measurement with an open and a blocked aperture gives it too).
share_coded = nominal.coded[0].sum(dim=(-2, -1)).numpy()[:, None, None]
share_plain = nominal.uncoded[0].sum(dim=(-2, -1)).numpy()[:, None, None]


def as_psf(raw, share):
    clean = np.clip(raw, 0, None)
    return torch.from_numpy(clean / clean.sum(axis=(-2, -1), keepdims=True) * share).float()[None]


measured = doefab.PSFPair(coded=as_psf(raw_coded, share_coded), uncoded=as_psf(raw_plain, share_plain),
                          wavelengths=nominal.wavelengths, depths=nominal.depths, sensor_pitch=nominal.sensor_pitch)
diff = (true_pair.coded - nominal.coded).abs().sum() / nominal.coded.sum()
print(f"the part's coded PSF differs from the design's by {float(diff) * 100:.1f} % (summed |difference|)")
err = (measured.coded - true_pair.coded).abs().sum() / true_pair.coded.sum()
print(f"the measurement differs from the part's PSF by {float(err) * 100:.1f} %")

# %%
# The green channel's coded PSF as designed, as made, and as measured (logarithmic scale):
reach = kernel / 2 * nominal.sensor_pitch * 1e6
fig, axes = plt.subplots(1, 3, figsize=(14, 4), layout="constrained")
for ax, (title, p) in zip(axes, [("design", nominal.coded), ("the part", true_pair.coded),
                                 ("measured", measured.coded)]):
    im = ax.imshow(np.log10(np.clip(p[0, 1].numpy(), 1e-7, None)), vmin=-7, vmax=-1, cmap="magma",
                   extent=(-reach, reach, -reach, reach))
    ax.set(title=f"coded PSF, {title}", xlabel="x on the sensor (µm)", ylabel="y on the sensor (µm)")
fig.colorbar(im, ax=axes, label="log10 fraction of the light per pixel", shrink=0.85)

# %%
# Reconstruct with each PSF pair
# ------------------------------
# The part's captures of an HDR scene, reconstructed with the design's PSF pair (the default) and with the
# measured one (``psf=``):
size = 128
scene = 0.9 * transform.resize(data.coffee(), (size, size), anti_aliasing=True).astype(np.float32).transpose(2, 0, 1)
lum = scene.mean(axis=0)
scene[:, lum > np.quantile(lum, 0.97)] *= 60.0
coded, uncoded = doefab.simulate_captures(scene, true_pair, seed=0)
with_design = np.asarray(rec(coded, uncoded))
with_measured = np.asarray(rec(coded, uncoded, psf=measured))
highlight = (scene > 2).any(axis=0)
for name, x in (("design PSF", with_design), ("measured PSF", with_measured)):
    mse_h = ((x - scene) ** 2)[:, highlight].mean()
    print(f"{name:13s} RMSE {np.sqrt(((x - scene) ** 2).mean()):.3f}   highlight PSNR "
          f"{10 * np.log10(256.0 ** 2 / mse_h):.2f} dB (peak 2^8)")

# %%
# Where each reconstruction errs (absolute error of the mean of R, G and B):
fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), layout="constrained")
vmax = float(np.abs(with_design - scene).mean(axis=0).max())
for ax, (name, x) in zip(axes, (("design PSF", with_design), ("measured PSF", with_measured))):
    im = ax.imshow(np.abs(x - scene).mean(axis=0), vmin=0, vmax=vmax, cmap="viridis")
    ax.set(title=f"error with the {name}", xlabel="x (sensor pixels)", ylabel="y (sensor pixels)")
fig.colorbar(im, ax=axes, label="|radiance error|", shrink=0.85)

"""
Simulate captures and reconstruct
=================================

A split-aperture camera records two images at once: the **coded** capture through the DOE half and the
**uncoded** capture through the plain half. This tutorial takes a photograph, makes it a high-dynamic-range
scene, simulates both captures through the committed streak design (sensor response, noise, clipping), and
reconstructs the radiance with the shipped HDR networks: the proposed one, which sees both captures, and the
two ablations that see only one.

The networks are the ones ``doefab run scenes/hdr.toml`` uses; ``doefab evaluate --task hdr --out out/eval``
scores them on held-out test scenes (see :doc:`/results/reconstruction`).
"""

# %%
# An HDR scene
# ------------
# Scene values are linear radiance in units of the sensor's clipping level for a full exposure: each
# capture receives half of the light (one aperture half), so radiance above 2 clips in the plain capture.
# Here the brightest 3 % of a photograph become 60 times brighter, as lamps and windows are.
import matplotlib.pyplot as plt
import numpy as np
from skimage import data, transform

import doefab

size = 128
photo = transform.resize(data.astronaut(), (size, size), anti_aliasing=True).astype(np.float32)
scene = 0.9 * photo.transpose(2, 0, 1)  # [3, H, W]: red, green, blue
luminance = scene.mean(axis=0)
scene[:, luminance > np.quantile(luminance, 0.97)] *= 60.0
print(f"radiance {scene.min():.2f} – {scene.max():.1f}; "
      f"{(scene > 2).any(axis=0).mean() * 100:.1f} % of the pixels clip in the plain capture")

# %%
# The shipped networks and their PSFs
# -----------------------------------
# ``load_reconstructor`` checks the weights against their record (checksum, design) and computes the PSF
# pair of the design they were trained for: ``rec.pair`` holds the coded and uncoded PSFs,
# ``[depths, wavelengths, K, K]`` fractions of the whole aperture's light per sensor pixel.
recs = {v: doefab.load_reconstructor("hdr", variant=v) for v in ("proposed", "coded_only", "uncoded_only")}
pair = recs["proposed"].pair
print("PSF window", tuple(pair.coded.shape), "at", [f"{w * 1e9:.0f} nm" for w in pair.wavelengths])
print(f"light in the window: coded {float(pair.coded.sum()) / 3:.3f}, uncoded {float(pair.uncoded.sum()) / 3:.3f} "
      f"of the aperture's (per wavelength)")

# %%
# Simulate the two captures
# -------------------------
# ``simulate_captures`` blurs each colour channel with its PSF, adds the default Poisson–Gaussian noise and
# clips to [0, 1]. The coded capture spreads each highlight into a long streak: near a bright highlight the
# streak clips too (and, spread over more pixels, it clips more of this frame than the plain capture does), but
# its far parts stay below clipping and still measure the highlight's radiance, which the plain capture's clipped
# pixels have lost.
coded, uncoded = doefab.simulate_captures(scene, pair, seed=0)
print("captures", coded.shape, coded.dtype, f"in [{coded.min():.2f}, {coded.max():.2f}]")
print(f"clipped pixels: coded {(coded >= 0.999).any(axis=0).mean() * 100:.2f} %, "
      f"uncoded {(uncoded >= 0.999).any(axis=0).mean() * 100:.2f} %")

# %%
# Reconstruct
# -----------
# ``rec(coded, uncoded)`` returns ``[3, H, W]`` linear radiance. The ablations take the same inputs and use
# only the capture they were trained with.
out = {v: np.asarray(r(coded, uncoded)) for v, r in recs.items()}
highlight = (scene > 2).any(axis=0)


def psnr(pred, mask=None, peak=256.0):
    """PSNR in dB with the HDR peak 2^8 (the metric of the results tables), over a mask of pixels or all."""
    err = (pred - scene) ** 2
    mse = err[:, mask].mean() if mask is not None else err.mean()
    return 10 * np.log10(peak ** 2 / mse)


for v, x in out.items():
    print(f"{v:13s} RMSE {np.sqrt(((x - scene) ** 2).mean()):6.3f}   PSNR {psnr(x):5.2f} dB   "
          f"highlight PSNR {psnr(x, highlight):5.2f} dB")

# %%
# The captures and the reconstructions, on a logarithmic scale of radiance (the colour bar is shared):
shown = [("scene", scene), ("coded capture × 2", 2 * coded), ("uncoded capture × 2", 2 * uncoded)]
shown += [(f"{v.replace('_', '-')} reconstruction", x) for v, x in out.items()]
fig, axes = plt.subplots(2, 3, figsize=(13, 8.4), layout="constrained")
for ax, (title, img) in zip(axes.flat, shown):
    lum = np.clip(img.mean(axis=0), 1e-3, None)
    im = ax.imshow(np.log10(lum), vmin=-2, vmax=np.log10(scene.max()), cmap="inferno")
    ax.set(title=title, xlabel="x (sensor pixels)", ylabel="y (sensor pixels)")
fig.colorbar(im, ax=axes, label="log10 radiance (1 = clipping level of a full exposure)", shrink=0.8)

# %%
# Radiance along one image row through the brightest highlight: the plain capture stops at its clipping
# level, the reconstructions recover the peak from the streak.
row = int(np.argmax(scene.mean(axis=0).max(axis=1)))
fig, ax = plt.subplots(figsize=(8, 3.6))
ax.semilogy(scene.mean(axis=0)[row], "k", lw=2, label="scene")
ax.semilogy(2 * uncoded.mean(axis=0)[row], "0.6", label="uncoded capture × 2")
for v, x in out.items():
    ax.semilogy(np.clip(x.mean(axis=0)[row], 1e-3, None), label=v.replace("_", "-"))
ax.set(xlabel="x (sensor pixels)", ylabel="radiance (mean of R, G, B)", title=f"row {row}")
ax.legend(fontsize=8)
fig.tight_layout()

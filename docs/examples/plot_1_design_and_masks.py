"""
Design a DOE for your camera and export its masks
=================================================

A DOE is designed for one camera: its aperture, DOE grid, lens-to-sensor distance and sensor pitch decide
where the light of each DOE pixel lands. This tutorial describes a camera, designs a streak DOE (the HDR
task) for it, looks at its point-spread functions (PSFs), and writes and verifies the four binary photomasks
a fab needs to etch its 16 levels.

The camera here is small so that the design takes seconds. For the prototype the same two steps are
``doefab design --task streak --out out/designs/streak`` and
``doefab masks --design out/designs/streak --out masks/streak --oasis``.
"""

# %%
# Describe the camera
# -------------------
# Every length is in metres. The DOE grid must cover the clear aperture; the lens focuses a point
# ``focus_distance`` away onto the sensor ``sensor_distance`` behind it.
import contextlib
import io
import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import doefab
from doefab.cli import main as doefab_command

camera = doefab.Camera(aperture_diameter=2.16e-3, doe_pitch=21.6e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                       sensor_distance=10e-3, focus_distance=5.0)
print(f"DOE grid {camera.doe_pixels}² pixels at {camera.doe_pitch * 1e6:g} µm, "
      f"clear aperture {camera.aperture_diameter * 1e3:g} mm")
print(f"focal length {camera.focal_length * 1e3:.3f} mm, working f-number {camera.f_number:.1f}")
print(f"one level step of fused silica at {camera.design_wavelength * 1e9:g} nm: "
      f"{doefab.level_step(camera) * 1e9:.2f} nm")

# %%
# Design the coded half
# ---------------------
# ``doefab.optimize`` runs the task's loss through the differentiable PSF model and quantizes the result to
# the 16 levels the masks make. The streak task puts the coded half's light on a cross of arms
# ``arm_px`` sensor pixels long; ``kernel_size`` is the simulated window in sensor pixels. Only the coded
# half (x < 0) is designed: the other half stays plain.
design = doefab.optimize("streak", iterations=40, camera=camera, task_params={"kernel_size": 31, "arm_px": 10},
                         lr=0.05, seed=0, progress=False)
m = design.metrics
print(m["name"])
print(f"continuous design {m['continuous']:.3f}, 16-level design {m['quantized']:.3f} "
      f"(worst wavelength {m['quantized_worst']:.3f})")

# %%
# The level map and the PSFs it makes, on a logarithmic scale. The PSFs are fractions of the whole
# aperture's light per sensor pixel; each half carries about 0.5 of it. The coded half spreads its light along
# the cross; the plain half keeps a compact spot.
pair = doefab.split_aperture_psf(design.quantized_height, camera, design.wavelengths, design.depths,
                                 kernel_size=31)
half = camera.doe_pixels * camera.doe_pitch / 2 * 1e3  # mm
k = pair.coded.shape[-1]
reach = k / 2 * camera.sensor_pitch * 1e6  # µm
fig, axes = plt.subplots(1, 4, figsize=(15, 3.6))
im = axes[0].imshow(design.levels, extent=(-half, half, -half, half), cmap="viridis")
axes[0].set(title="levels, seen from the scene", xlabel="x on the DOE (mm)", ylabel="y on the DOE (mm)")
fig.colorbar(im, ax=axes[0], label="level")
shown = [(f"coded PSF, {lam * 1e9:.0f} nm", psf) for lam, psf in zip(design.wavelengths[:2], pair.coded[0])]
shown.append((f"uncoded PSF, {design.wavelengths[0] * 1e9:.0f} nm", pair.uncoded[0, 0]))
for ax, (title, psf) in zip(axes[1:], shown):
    im = ax.imshow(np.log10(psf.numpy() + 1e-6), vmin=-5, vmax=-1, extent=(-reach, reach, -reach, reach),
                   cmap="magma")
    ax.set(title=title, xlabel="x on the sensor (µm)", ylabel="y on the sensor (µm)")
    fig.colorbar(im, ax=ax, label="log10 fraction of the light per pixel")
fig.tight_layout()

# %%
# The design's progress: ``design.history`` holds (step, wall time in s, loss, metric) rows.
hist = np.array([row[:3] for row in design.history], dtype=float)
fig, ax = plt.subplots(figsize=(5, 3.2))
ax.plot(hist[:, 0], hist[:, 2])
ax.set(xlabel="optimiser step", ylabel="loss (1 − fraction in the band)", title="streak design")
fig.tight_layout()

# %%
# Save the design and export its masks
# ------------------------------------
# A design folder (``design.json``, ``levels.npy``, figures) is what the mask export, the holder and the
# tolerance study read. ``doefab masks`` writes the GDSII layout (``--oasis``: an OASIS copy too), reads it
# back, rasterises every etch layer and compares it with the level map pixel by pixel before it moves the set
# into place. It runs here through ``doefab.cli.main``, exactly as on a command line.
work = Path(tempfile.mkdtemp(prefix="doefab-tutorial-"))
design.save(work / "design")
status = doefab_command(["masks", "--design", str(work / "design"), "--out", str(work / "masks"), "--oasis"])
print("exit status", status)
print(sorted(p.name for p in (work / "masks").iterdir()))

# %%
# What the fab reads: ``manifest.json`` (every layer's etch depth, tolerance, polarity, process step and
# alignment; see :doc:`/fab/mask-set`) and ``README.txt``.
manifest = json.loads((work / "masks" / "manifest.json").read_text())
for layer in sorted(manifest["layers"], key=lambda x: x["process_step"]):
    depth = f"{layer['etch_depth_nm']:8.3f} nm" if "etch_depth_nm" in layer else "  (chrome)  "
    to = layer["aligns_to_plate"]
    print(f"step {layer['process_step']}: layer {layer['layer']}  {depth}  "
          + ("written first" if to is None else f"aligns to plate {to}"))
print("layout mirrored in x:", manifest["mirrored_x"])

# %%
# The layout is drawn as seen from its patterned face. The holder mounts that face toward the lens, so the
# layout is the design mirrored in x: the coded half, on the left seen from the scene, is on the right of the
# layout. Bit ``m`` of ``15 − level`` says whether mask ``m + 1`` etches a pixel.
layout = design.levels[:, ::-1] if manifest["mirrored_x"] else design.levels
fig, axes = plt.subplots(1, 5, figsize=(16, 3.4))
axes[0].imshow(layout, extent=(-half, half, -half, half), cmap="viridis")
axes[0].set(title="layout (from the patterned face)", xlabel="x (mm)", ylabel="y (mm)")
for bit, ax in enumerate(axes[1:]):
    ax.imshow((15 - layout.astype(int)) >> bit & 1, extent=(-half, half, -half, half), cmap="gray_r")
    ax.set(title=f"layer {bit + 1}: etched {2 ** bit}·d (dark)", xlabel="x (mm)", ylabel="y (mm)")
fig.tight_layout()

# %%
# Anyone can re-check a mask set later; the command prints the whole verification report, and its last line
# says the result (exit status 3 and the failing field if anything disagrees):
with contextlib.redirect_stdout(io.StringIO()) as printed:
    status = doefab_command(["masks", "--verify", str(work / "masks")])
print(printed.getvalue().splitlines()[-1])
print("exit status", status)

"""
Build, check and fit the holder
===============================

The holder mounts the DOE die in front of the lens: a **base ring** that screws into the lens's filter thread
(or slips over its barrel) and a **cartridge** that holds the die in a keyed pocket, so the die fits one way
only and the split line can be turned and locked. Both print flat and support-free. This tutorial fits the
holder to a lens, builds it, reads its checks, and shows what happens when a parameter does not fit.

Every holder length is in **millimetres** (the CAD convention). On the command line the same build is
``doefab holder --out out/holder --set thread_diameter_mm=52``.
"""

# %%
# Fit the parameters to your lens
# -------------------------------
# The defaults fit the Canon EF 50 mm f/1.8 STM (49 mm filter thread) and a 12 mm × 12 mm die. Here the lens
# has a 52 mm filter thread; the thread's pitch and the flange follow from it. ``lens_face_to_glass_mm`` (from
# the filter face to the front glass) sets how far the DOE sits from the lens: measure it on your lens.
import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from holder_cad import HolderError, HolderParams, build_parts, write_holder

params = HolderParams(thread_diameter_mm=52.0, lens_face_to_glass_mm=3.5)
print(f"M{params.thread_diameter_mm:g} × {params.thread_pitch_mm:g} thread, flange {params.flange_diameter_mm:g} mm "
      f"across and {params.flange_height_mm:g} mm high (derived: {', '.join(params.derived)})")
print(f"DOE to lens glass (from the parameters): {params.doe_to_lens_mm:.2f} mm")
print(f"die pocket: {params.die_width_mm:g} × {params.die_height_mm:g} mm with {params.clearance_mm:g} mm "
      f"clearance per side")

# %%
# A parameter set that cannot work is refused before anything is built, with the quantity and the fix:
try:
    HolderParams(thread_diameter_mm=52.0, clearance_mm=0.02)
except HolderError as err:
    print("refused:", err)

# %%
# Build and check
# ---------------
# ``write_holder`` builds both bodies, runs every check on the meshes and writes the printable files only if
# all pass. STEP (through cadquery) is skipped here to keep the tutorial quick; the command line writes it
# when cadquery is installed.
out = Path(tempfile.mkdtemp(prefix="doefab-holder-"))
report = write_holder(params, out, step=False, renders=True)
print("files:", ", ".join(report["files"]))
checks = report["checks"]
print("every check passed:", checks["passed"])
print(f"DOE to lens glass, measured on the mesh: {report['doe_to_lens_mm']:.2f} mm")

# %%
# ``holder.json`` keeps each derived quantity that decides the fit with its bounds (millimetres unless the
# unit says otherwise):
record = json.loads((out / "holder.json").read_text())
for b in record["checks"]["fit_bounds"]:
    print(f"{b['quantity']:28s} {b['value']:8.3f} {b['unit']:6s} allowed {b['min']:g} – {b['max']:g}  "
          f"{'ok' if b['ok'] else 'FAILS'}")

# %%
# A cross-section of the two bodies in print orientation, straight from the meshes (``build_parts``): the
# base ring with its thread teeth, and the cartridge with the die pocket near its bottom.
parts = build_parts(params)
fig, axes = plt.subplots(1, 2, figsize=(12, 3.8))
for ax, (name, body) in zip(axes, parts.items()):
    # turn the y = 0 plane into the z = 0 plane (z becomes −y), then cut there: the points are (x, −z)
    section = body.rotate((90.0, 0.0, 0.0)).slice(0.0).to_polygons()
    for ring in section:
        pts = np.asarray(ring)
        ax.fill(pts[:, 0], -pts[:, 1], color="#4878cf" if name == "base" else "#d65f5f", alpha=0.8)
    ax.set_aspect("equal")
    ax.set(title=f"{name}: section through the axis", xlabel="x (mm)", ylabel="height on the print bed (mm)")
fig.tight_layout()

# %%
# The assembled holder as ``write_holder`` renders it (``render_side.png``: cut through the axis, lens side
# down, scene side up):
img = plt.imread(out / "render_side.png")
fig, ax = plt.subplots(figsize=(6, 5))
ax.imshow(img)
ax.set_axis_off()

# %%
# Print, then fit
# ---------------
# Print ``coupon.stl`` first: a die pocket and a ring with the base's thread and bore under a grip rim, less than
# half the base's plastic. If the die does not drop into the pocket, raise ``clearance_mm``; if the ring does not
# turn into the filter thread, raise ``thread_clearance_mm`` (the table above gives the most it may be); if it
# turns but wobbles, lower it. Rebuild and print ``holder.stl`` (or ``holder.3mf``).
#
# The clearances also decide how well the DOE is aligned. ``doefab tolerance --holder holder.json`` takes the
# decenter and rotation a built holder allows, and its measured DOE-to-lens distance, into the tolerance
# study (see the tolerance tutorial), for example for a holder built with ``doefab holder --out out/holder``:
#
# .. code-block:: bash
#
#    doefab tolerance --design masks/streak --holder out/holder/holder.json --samples 200 --out out/tol/streak

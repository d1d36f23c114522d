"""
Judge a part's tolerance and read its yield
===========================================

A fab does not make the design: every etch is a little too deep or too shallow, every mask lands a little off,
and the holder leaves the die some play. This tutorial makes one fabricated part by hand to see what each error
does, then runs ``doefab tolerance``: each error alone at its budget value (a tornado ranking) and a Monte
Carlo over many parts, whose **yield** — the fraction of parts that meet the spec — comes with a confidence
interval that says how many parts the decision needs.

For a committed design the command is ``doefab tolerance --design masks/grating --samples 300 --out
out/tol/grating``; here it runs on a small design so that it takes seconds.
"""

# %%
# A design to judge
# -----------------
# The small camera and streak design of the first tutorial.
import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

import doefab
from doefab.cli import main as doefab_command

camera = doefab.Camera(aperture_diameter=2.16e-3, doe_pitch=21.6e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                       sensor_distance=10e-3, focus_distance=5.0)
task_params = {"kernel_size": 31, "arm_px": 10}
design = doefab.optimize("streak", iterations=40, camera=camera, task_params=task_params, lr=0.05, seed=0,
                         progress=False)
work = Path(tempfile.mkdtemp(prefix="doefab-tolerance-"))
design.save(work / "design")
task = doefab.get_task("streak", **task_params)


def metric(height):
    """The task metric (fraction of the coded light on the cross's arms, within 1 px and off its centre) of a height
    map in metres."""
    pair = doefab.split_aperture_psf(height, camera, design.wavelengths, design.depths, kernel_size=31,
                                     halves=("coded",))
    return task.metric(pair.coded, camera)["value"]


nominal = metric(design.quantized_height)
print(f"nominal 16-level part: {nominal:.4f}")

# %%
# One part, one error at a time
# -----------------------------
# ``fabricated_height`` builds the relief from the four masks: mask ``m`` etches ``2^m`` level steps, so an
# etch-depth error scales exactly that mask's steps and an overlay error moves exactly the pixels that mask
# etches. Depth scales are relative (1.05 = 5 % too deep), overlays in metres.
scales = [0.90, 0.95, 1.0, 1.05, 1.10]
by_depth = [metric(doefab.fabricated_height(design.levels, camera, camera.design_wavelength,
                                            depth_scale=(s,) * 4, supersample=1)) for s in scales]
shift = 3e-6  # metres: a 3 µm misalignment of one mask
by_mask = []
for m in range(4):
    overlay = [(0.0, 0.0)] * 4
    overlay[m] = (shift, 0.0)
    by_mask.append(metric(doefab.fabricated_height(design.levels, camera, camera.design_wavelength,
                                                   overlay=overlay, supersample=1)))
fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
axes[0].plot([100 * (s - 1) for s in scales], by_depth, "o-")
axes[0].set(xlabel="etch depth error, every mask (%)", ylabel="task metric", title="etch depth")
axes[1].bar([f"layer {m + 1}\n(etches {2 ** m}·d)" for m in range(4)], [v - nominal for v in by_mask])
axes[1].axhline(0, color="k", lw=0.8)
axes[1].set(ylabel="change of the task metric", title=f"one mask shifted by {shift * 1e6:g} µm in x")
fig.tight_layout()

# %%
# A shifted mask leaves slivers of misplaced relief along the edges of what it etches, each with the phase
# error of that mask's step (2^m·d): how much that costs depends on the design.
for m, v in enumerate(by_mask):
    print(f"layer {m + 1} shifted {shift * 1e6:g} µm: metric {v:.4f} ({v - nominal:+.4f})")

# %%
# A budget for this part
# ----------------------
# A budget file gives every error's size: its unit is in its key (``_percent``, ``_um``, ``_mm``, ``_deg``);
# keys it leaves out take the shipped budget's values (``doefab/tolerance/budget.toml``, which documents
# each). The shipped mounting errors are those of the prototype's 8.64 mm die pocket; this small part gets a
# tighter mount. The spec says what a part must deliver: here a metric of at least 0.8.
budget = work / "budget.toml"
budget.write_text("""
[mounting]
decenter_max_mm = 0.01
rotation_sigma_deg = 0.2

[spec.hdr]
psf_metric_min = 0.8
""")

# %%
# Run the study
# -------------
# ``--samples`` parts are drawn from the budget, each from its own random stream (so the numbers do not depend
# on how the work is split); ``--grid 1`` simulates every part on the design's own grid (the default,
# ``--grid auto``, first measures which grid each error needs). Parts are saved as they finish:
# ``--resume`` continues an interrupted study.
status = doefab_command(["tolerance", "--design", str(work / "design"), "--budget", str(budget),
                         "--samples", "40", "--grid", "1", "--out", str(work / "tol")])
print("exit status", status)

# %%
# Read the yield
# --------------
# ``tolerance.json`` holds every part and the summaries. The yield's 95 % Wilson interval is the honest
# answer to "what fraction of parts will meet the spec"; with few parts it is wide.
result = json.loads((work / "tol" / "tolerance.json").read_text())
y = result["summary"]["yield"]
print(f"spec: {result['spec']['psf']}")
print(f"yield {y['value']:.2f} of {y['n']} parts, 95 % interval {y['ci95'][0]:.2f} – {y['ci95'][1]:.2f}")
mean = result["summary"]["metric"]
print(f"metric mean {mean['mean']:.4f}, 95 % interval of the mean {mean['ci95'][0]:.4f} – {mean['ci95'][1]:.4f}")

# %%
# What limits the part (each error alone at its budget value) and how the yield interval narrows with the
# number of parts:
tornado = sorted(result["tornado"], key=lambda r: abs(r["delta"]))
conv = result["convergence"]
fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
axes[0].barh([f"{r['error']} ({r['value']:g} {r['unit']})" for r in tornado], [r["delta"] for r in tornado])
axes[0].set(xlabel="change of the task metric", title="each error alone at its budget value")
axes[1].plot([c["n"] for c in conv], [c["yield_ci95_width"] for c in conv], "o-")
axes[1].set(xlabel="parts simulated", ylabel="width of the yield's 95 % interval", title="how many parts")
fig.tight_layout()

# %%
# ``report.md`` says the same in words, starting with what the part delivers and what would buy the most:
print("\n".join((work / "tol" / "report.md").read_text().splitlines()[:8]))

"""
Scale a Monte Carlo out to a Dask cluster
=========================================

A yield decision at ±5 % needs a few hundred simulated parts, and a full-size design takes seconds per part.
``doefab tolerance`` hands its parts to a Dask scheduler: ``--scheduler local:N`` starts a ``LocalCluster``
of N worker processes on this machine, ``--scheduler tcp://HOST:PORT`` uses a cluster that is already running
(more machines, a batch system). Every part draws from its own random stream, so the numbers are the same in
process, in a process pool and on any cluster.

This tutorial starts a two-worker ``LocalCluster`` itself, runs the same small study in process and on the
cluster, and compares the parts.
"""

# %%
# A design and a study
# --------------------
# The small camera and streak design of the first tutorial, and a budget with a tight mount for it.
import json
import tempfile
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from dask.distributed import LocalCluster

import doefab
from doefab.cli import main as doefab_command

camera = doefab.Camera(aperture_diameter=2.16e-3, doe_pitch=21.6e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                       sensor_distance=10e-3, focus_distance=5.0)
design = doefab.optimize("streak", iterations=40, camera=camera, task_params={"kernel_size": 31, "arm_px": 10},
                         lr=0.05, seed=0, progress=False)
work = Path(tempfile.mkdtemp(prefix="doefab-dask-"))
design.save(work / "design")
(work / "budget.toml").write_text("[mounting]\ndecenter_max_mm = 0.01\nrotation_sigma_deg = 0.2\n")
study = ["tolerance", "--design", str(work / "design"), "--budget", str(work / "budget.toml"), "--samples", "16",
         "--grid", "1", "--seed", "7"]

# %%
# In process
# ----------
t0 = time.perf_counter()
doefab_command(study + ["--out", str(work / "in_process")])
seconds_in_process = time.perf_counter() - t0

# %%
# On a cluster
# ------------
# A ``LocalCluster`` stands in for a real one: two worker processes of one thread each, no dashboard. On a
# cluster of many machines, start the scheduler and the workers there (``dask scheduler``, ``dask worker
# tcp://HOST:8786``) and pass the scheduler's address the same way. Each worker rebuilds the PSF model from
# the design folder once, so the folder must be readable where the workers run.
with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
    print("scheduler at", cluster.scheduler_address)
    t0 = time.perf_counter()
    doefab_command(study + ["--scheduler", cluster.scheduler_address, "--out", str(work / "cluster")])
    seconds_cluster = time.perf_counter() - t0
print(f"in process {seconds_in_process:.1f} s, on the cluster {seconds_cluster:.1f} s (including each worker's "
      f"start-up)")

# %%
# The same parts
# --------------
# The parts come back in the order they finish; sorted by their index, the two runs hold the same errors and
# the same metrics (up to float32 rounding, as torch may sum in another order with another thread count).
runs = {}
for name in ("in_process", "cluster"):
    result = json.loads((work / name / "tolerance.json").read_text())
    runs[name] = sorted(result["samples"], key=lambda s: s["index"])
a = np.array([s["metric"] for s in runs["in_process"]])
b = np.array([s["metric"] for s in runs["cluster"]])
same_errors = all(x["errors"] == y["errors"] for x, y in zip(runs["in_process"], runs["cluster"]))
print(f"{len(a)} parts each; same drawn errors: {same_errors}; largest metric difference {np.abs(a - b).max():.2e}")

fig, ax = plt.subplots(figsize=(5, 4.2))
ax.plot(a, b, "o")
lims = (min(a.min(), b.min()) - 0.005, max(a.max(), b.max()) + 0.005)
ax.plot(lims, lims, "k:", lw=1)
ax.set(xlim=lims, ylim=lims, xlabel="task metric, in process", ylabel="task metric, on the cluster",
       title="the same 16 parts")
fig.tight_layout()

# %%
# On two cores a cluster is not faster than the in-process run (torch already uses both cores, and each worker
# sets up its own PSF model); it pays off when the workers are on more machines. An interrupted study on a
# cluster continues with ``--resume``: finished parts are in ``samples.jsonl``.

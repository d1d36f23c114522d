"""What the shipped hyperspectral networks were trained on, against today's split definition.

Their weights records name another split definition than today's (``doefab evaluate`` says "ANOTHER split
definition: the test scenes may hold training content"): they were trained at the commit that last wrote
``doefab/weights/hyperspectral_proposed.pt``, before the same-surface tolerance between the splits' reflectances
was widened to 0.13 and before every held-out scene was lit by light outside the illuminant library. This script
runs that commit's scene content (a temporary git worktree, its own ``doefab.reconstruction.spectra`` and
``data``) beside today's and compares what training draws from and what the held-out splits hold:

- the photographs and scene seeds of every split; the training split's measured reflectances; the synthetic
  training reflectances (the same seeded draws); the lights of the training scenes (the same seeded draws);
  the illuminant library's file;
- today's validation, test and measured-set reflectances and lights against everything training held then:
  the nearest training reflectance to each (``spectra.spectral_distance``), and whether each held-out light is
  one of the training scenes' lights.

    .venv/bin/python benchmarks/spectra_training_content.py [--trained-at COMMIT]

Writes benchmarks/results/spectra_training_content.md. Takes about a minute (colour-science's collections).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from doefab.io import atomic_write_text  # noqa: E402

OUT = REPO / "benchmarks" / "results" / "spectra_training_content.md"
DRAWS = 400  # seeded synthetic reflectances and training-scene lights compared draw by draw

# run in the old and in today's code alike (only names both versions have)
DUMP = """
import hashlib, json, sys
import numpy as np
from doefab.reconstruction import data, spectra
from doefab.reconstruction.illuminant import LIBRARY_PATH

rng = np.random.default_rng(20261205)
syn = np.stack([spectra.synthetic_reflectance(rng) for _ in range(DRAWS)])
rng = np.random.default_rng(20261206)
lights = np.stack([spectra.scene_illuminant(rng, "train", spectra.light_kind("train", i)) for i in range(DRAWS)])
np.savez(sys.argv[1], train=spectra.reflectances("train"), val=spectra.reflectances("val"),
         test=spectra.reflectances("test"), val_lights=spectra.val_lights(), test_lights=spectra.test_lights(),
         synthetic=syn, train_lights=lights)
names = {"images": data.IMAGES, "seeds": {s: data.SPLIT_SEEDS[s] for s in ("train", "val", "test")},
         "library_sha256": hashlib.sha256(LIBRARY_PATH.read_bytes()).hexdigest()}
print(json.dumps(names, sort_keys=True))
""".replace("DRAWS", str(DRAWS))


def trained_at() -> str:
    """The commit that last wrote the shipped proposed hyperspectral network's weights."""
    return subprocess.run(["git", "-C", str(REPO), "log", "-1", "--format=%H", "--",
                           "doefab/weights/hyperspectral_proposed.pt"], capture_output=True, text=True,
                          check=True).stdout.strip()


def dump(root: Path, out: Path) -> dict:
    """Run ``DUMP`` with the package at ``root``; returns its names and seeds (the arrays go to ``out``)."""
    env = {**os.environ, "PYTHONPATH": str(root), "OMP_NUM_THREADS": "1"}
    got = subprocess.run([sys.executable, "-c", DUMP, str(out)], capture_output=True, text=True, env=env,
                         cwd=str(root), check=True)
    return json.loads(got.stdout.strip().splitlines()[-1])


def nearest(held: np.ndarray, train: np.ndarray) -> np.ndarray:
    """Each held-out reflectance's distance to its nearest training reflectance."""
    from doefab.reconstruction import spectra

    return np.array([min(spectra.spectral_distance(h, t) for t in train) for h in held])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trained-at", default=None, help="the commit the networks were trained at (default: the "
                    "commit that last wrote doefab/weights/hyperspectral_proposed.pt)")
    args = ap.parse_args()
    commit = args.trained_at or trained_at()

    with tempfile.TemporaryDirectory() as tmp:
        wt = Path(tmp) / "then"
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "-q", str(wt), commit], check=True)
        try:
            then_names = dump(wt, Path(tmp) / "then.npz")
        finally:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(wt)], check=True)
        now_names = dump(REPO, Path(tmp) / "now.npz")
        then, now = dict(np.load(Path(tmp) / "then.npz")), dict(np.load(Path(tmp) / "now.npz"))
    same = {"photographs and seeds of train, val, test": then_names["images"] == now_names["images"]
            and then_names["seeds"] == now_names["seeds"],
            "illuminant library file (SHA-256)": then_names["library_sha256"] == now_names["library_sha256"]}
    for k, what in (("train", "training split's measured reflectances"),
                    ("synthetic", f"synthetic training reflectances ({DRAWS} seeded draws)"),
                    ("train_lights", f"training scenes' lights ({DRAWS} seeded draws)")):
        same[what] = then[k].shape == now[k].shape and bool(np.array_equal(then[k], now[k]))
    train = np.concatenate([then["train"], then["synthetic"]])
    held = {"validation (and the measured set, which takes its reflectances)": now["val"], "test": now["test"]}
    rows = [(name, len(r), float(nearest(r, then["train"]).min()), float(nearest(r, train).min()))
            for name, r in held.items()]
    lib_lights = {hashlib.sha256(np.round(x, 6).tobytes()).hexdigest() for x in then["train_lights"]}
    shared_lights = sum(hashlib.sha256(np.round(x, 6).tobytes()).hexdigest() in lib_lights
                        for x in np.concatenate([now["val_lights"], now["test_lights"]]))
    lines = [f"`.venv/bin/python benchmarks/spectra_training_content.py`: the scene content of the commit the shipped "
             f"hyperspectral networks were trained at ({commit[:12]}) against today's.", "",
             "| what training draws from | identical then and now |", "| --- | --- |"]
    lines += [f"| {k} | {'yes' if v else 'NO'} |" for k, v in same.items()]
    kept = {k: all(any(np.array_equal(r, o) for o in then[k]) for r in now[k]) for k in ("val", "test")}
    lines += ["", f"Then: validation {len(then['val'])}, test {len(then['test'])} measured reflectances; now "
              f"{len(now['val'])} and {len(now['test'])}, each "
              + ("one of then's" if all(kept.values()) else "NOT all among then's") + ".", "",
              "| held-out today | reflectances | nearest measured training one (then) | nearest training one, "
              f"{DRAWS} synthetic draws included |", "| --- | --- | --- | --- |"]
    lines += [f"| {n} | {k} | {a:.3f} | {b:.3f} |" for n, k, a, b in rows]
    lines += ["", f"Held-out lights (validation and test) equal to a training scene's light: {shared_lights} of "
              f"{len(now['val_lights']) + len(now['test_lights'])}. The measured set's scenes are lit by two "
              f"displays' RGB primaries, which neither split nor the library holds."]
    atomic_write_text(OUT, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()

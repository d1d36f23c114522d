"""How far the hyperspectral splits' reflectances and lights lie from each other: the gaps between two
measurements of one ColorChecker patch (which set the "one surface" tolerance ``spectra.DUPLICATE``), the
nearest pairs of reflectances between training and the held-out splits, the spectra the tolerance keeps out of
validation and test, how close the synthetic training reflectances come to test ones, and how close each
held-out light comes to the illuminant library that lights every training scene.

    .venv/bin/python benchmarks/spectra_nearest_pairs.py [--draws 3000]

Writes benchmarks/results/spectra_nearest_pairs.md. Distances are ``spectra.spectral_distance`` (max absolute
difference on the 31 bands 400–700 nm after a least-squares scale) for reflectances, and the max absolute
difference at peak 1 for lights. Takes a few seconds.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_text  # noqa: E402
from doefab.reconstruction import spectra  # noqa: E402
from doefab.reconstruction.illuminant import LIBRARY_PATH, illuminant_library  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "spectra_nearest_pairs.md"
HELD = ("val", "test")


def same_patch_gaps() -> list[tuple[str, float]]:
    """(patch, distance) between colour-science's N Ohta and BabelColor measurements of each ColorChecker patch,
    largest first."""
    from colour.characterisation import SDS_COLOURCHECKERS

    ohta, babel = SDS_COLOURCHECKERS["ColorChecker N Ohta"], SDS_COLOURCHECKERS["BabelColor Average"]
    gaps = [(n, spectra.spectral_distance(*(np.clip(spectra.on_bands(c[n]), 0, 1) for c in (ohta, babel))))
            for n in ohta]
    return sorted(gaps, key=lambda g: -g[1])


def pairs(a: str, b: str, step_b: int = 2) -> list[tuple[float, str, str]]:
    """(distance, name in ``a``, name in ``b``) of every pair of split ``a``'s and split ``b``'s reflectances
    (``b`` after ``step_b``), nearest first."""
    ra, na = spectra.reflectances(a), spectra.reflectance_names(a)
    rb, nb = spectra.reflectances(b, step_b), spectra.reflectance_names(b, step_b)
    out = [(spectra.spectral_distance(x, y), n, m) for x, n in zip(ra, na) for y, m in zip(rb, nb)]
    return sorted(out)


def gap_lines() -> list[str]:
    gaps = same_patch_gaps()
    d = np.array([g for _, g in gaps])
    lines = ["## Two measurements of one surface", "",
             f"The 24 ColorChecker patches as colour-science's N Ohta and BabelColor Average data measure them: "
             f"median gap {np.median(d):.3f}, 95th percentile {np.percentile(d, 95):.3f}, largest {d.max():.3f} "
             f"({gaps[0][0]}). Spectra closer than `DUPLICATE` = {spectra.DUPLICATE} count as one surface: at the "
             f"95th percentile {int((d > np.percentile(d, 95)).sum())} of the 24 patches' second measurements "
             f"would pass as another surface, at {spectra.DUPLICATE} none does "
             f"({int((d > spectra.COPY).sum())} do at the copy tolerance `COPY` = {spectra.COPY}).", "",
             "| patch | gap |", "| --- | --- |"]
    return lines + [f"| {n} | {g:.3f} |" for n, g in gaps[:8]] + [""]


def removed_lines() -> list[str]:
    lines = ["## Held-out reflectances a training one is too close to", "",
             f"Every validation and test spectrum (after copies are removed) within {spectra.DUPLICATE} of a training "
             "one, with its nearest training spectrum: none of them lights a validation or test scene.", "",
             "| split | held-out spectrum | nearest training spectrum | distance |", "| --- | --- | --- | --- |"]
    for split in HELD:
        near = {}
        for dist, t, h in pairs("train", split, step_b=1):
            if dist <= spectra.DUPLICATE and h not in near:
                near[h] = (t, dist)
        kept = set(spectra.reflectance_names(split))
        assert not kept & set(near), "a spectrum too close to training is still held out"
        ranked = sorted(near.items(), key=lambda x: x[1][1])
        lines += [f"| {split} | {h} | {t} | {dist:.3f} |" for h, (t, dist) in ranked]
        lines.append(f"| {split} | ({len(near)} removed, {len(kept)} kept) | | |")
    return lines + [""]


def nearest_lines(rows: int) -> list[str]:
    lines = ["## Nearest pairs between the splits the scenes use", "",
             f"The {rows} nearest pairs of each pair of splits. Training and the held-out splits stay more than "
             f"{spectra.DUPLICATE} apart; validation and test are kept apart by the copy tolerance {spectra.COPY} only "
             "(no network trains on validation: it records the training curves and chooses settings).", "",
             "| splits | spectrum | spectrum | distance |", "| --- | --- | --- | --- |"]
    for a, b in (("train", "test"), ("train", "val"), ("val", "test")):
        ps = pairs(a, b)
        lines += [f"| {a}–{b} | {n} | {m} | {d:.3f} |" for d, n, m in ps[:rows]]
        lines.append(f"| {a}–{b} | ({sum(d <= spectra.DUPLICATE for d, _, _ in ps)} of {len(ps)} pairs within "
                     f"{spectra.DUPLICATE}) | | |")
    return lines + [""]


def synthetic_lines(draws: int) -> list[str]:
    rng = np.random.default_rng(0)
    test = spectra.reflectances("test")
    drawn = [spectra.synthetic_reflectance(rng) for _ in range(draws)]
    d = np.array([min(spectra.spectral_distance(r, t) for t in test) for r in drawn])
    return ["## Synthetic training reflectances", "",
            f"Of {draws} smooth synthetic reflectances drawn as training draws them (kept {spectra.COPY} from the "
            f"held-out families, the rule the shipped networks were trained under), "
            f"{100 * (d <= spectra.DUPLICATE).mean():.1f} % lie within {spectra.DUPLICATE} of a test reflectance "
            f"(nearest {d.min():.3f}, median {np.median(d):.3f}): the networks have seen smooth spectra as near the "
            "test's as two measurements of one patch are, though none of the test's measured ones.", ""]


def light_lines(rows: int) -> list[str]:
    import csv

    with open(LIBRARY_PATH, newline="") as f:
        names = [r[0] for r in list(csv.reader(f))[1:]]
    lib = illuminant_library()
    lines = ["## Held-out lights against the library", "",
             f"Training scenes are lit by the {len(lib)} members of the illuminant library, validation and test "
             "scenes only by light outside it. The measured held-out lights nearest to a member (max absolute "
             "difference, both at peak 1; a light within 0.02 counts as a member and is not used):", "",
             "| split | light | nearest library member | distance |", "| --- | --- | --- | --- |"]
    for split, found in zip(HELD, spectra.held_out_light_sources()):
        near = sorted((float(np.abs(lib - e).max(axis=1).min()), n, names[int(np.abs(lib - e).max(axis=1).argmin())])
                      for n, e in found.items())
        lines += [f"| {split} | {n} | {m} | {d:.3f} |" for d, n, m in near[:rows]]
        lines.append(f"| {split} | ({len(near)} lights, farthest {near[-1][0]:.3f}) | | |")
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=3000, help="synthetic training reflectances to draw")
    args = ap.parse_args()
    counts = ", ".join(f"{s} {len(spectra.reflectances(s))}" for s in ("train", "val", "test"))
    lines = ["# Nearest spectra between the hyperspectral splits", "",
             f"Measured reflectances per split: {counts} (`.venv/bin/python benchmarks/spectra_nearest_pairs.py`).",
             ""]
    lines += gap_lines() + removed_lines() + nearest_lines(8) + synthetic_lines(args.draws) + light_lines(6)
    atomic_write_text(OUT, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()

"""``doefab diagnose``: which fab and mount errors a part has, fitted to its measured PSF pair, and what to do.

Examples:
  doefab diagnose --psf out/cal/psf_pair.npz --out out/diag
  doefab diagnose --psf out/cal/psf_pair.npz --design masks/streak --starts 6 --delivered --out out/diag

Fits the part model that the tolerance study draws parts from (per mask: etch depth scale and overlay; edge
bias; the mount's decenter, rotation and axial gap) to the measured pair, from several starts. Writes
OUT/diagnosis.json (each error with its uncertainty and whether the recordings identify it, each against the
budget in σ, the misfit, the PSF metric nominal, as measured and as fitted), OUT/psf_pair_fitted.npz (the fitted
part's pair at every band and plane of the design: give it to the networks with --psf) and OUT/diagnosis.html
(in words first: what the part delivers, what lies outside the budget, what to do).
"""

from __future__ import annotations

import argparse

from doefab.cli._args import add_device_arg, number


def register(sub) -> None:
    p = sub.add_parser("diagnose", help="fit a fabricated part's errors to its measured PSF pair",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--psf", required=True, help="the measured PSF pair (psf_pair.npz from doefab calibrate)")
    p.add_argument("--design", default=None,
                   help="the design folder (or mask set, or shipped design's name) the part was made from; "
                        "default: the design the pair's calibration names")
    p.add_argument("--budget", default=None, help="the tolerance budget (TOML) the errors are judged against; "
                                                  "default: the shipped one")
    p.add_argument("--starts", type=number(int, 1, 100, unit="fits"), default=None,
                   help="fits from the error-free part and from parts drawn from the budget; the best is kept "
                        "(default 8: doefab.lab.diagnose.STARTS)")
    p.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0,
                   help="seed of the starts' draws and of the held errors' draws")
    p.add_argument("--delivered", action="store_true",
                   help="also judge the fitted part through the task's shipped network (a few minutes on a CPU)")
    p.add_argument("--out", required=True, help="output folder (diagnosis.json, psf_pair_fitted.npz, diagnosis.html)")
    p.add_argument("--force", action="store_true", help="replace an earlier diagnose output in OUT")
    add_device_arg(p)
    p.set_defaults(func=run)


def design_of(pair, given) -> str:
    """The design folder: ``--design``, else the one the pair's provenance names (refused, with the fix, when it
    names none or one that is not a folder here)."""
    from pathlib import Path

    from doefab.errors import DoefabError

    if given:
        return given
    named = (getattr(pair, "provenance", None) or {}).get("design")
    if not named or named == "None":
        raise DoefabError("--design is needed: the pair's provenance names no design; give the design folder (or mask "
                          "set) the part was made from, e.g. --design masks/streak")
    if not Path(named).is_dir():
        raise DoefabError(f"--design is needed: the pair was calibrated with the design {named}, which is not a folder "
                          f"here; give the design folder (or mask set) the part was made from, e.g. --design "
                          f"masks/streak")
    return named


def run(args) -> int:
    from doefab.cli._args import design_folder
    from doefab.cli._output import claim_output
    from doefab.io import atomic_write_json
    from doefab.lab.diagnose import diagnose, fitted_pair
    from doefab.lab.diagreport import check_design, write_report
    from doefab.lab.partmodel import check_pair
    from doefab.optics.psf import PSFPair
    from doefab.optics.psffile import save_psf_pair
    from doefab.tolerance.errors import load_budget

    pair = PSFPair.load(args.psf)
    folder, design = design_folder(design_of(pair, args.design))
    check_design(pair, design)
    check_pair(pair, design)
    budget = load_budget(args.budget)
    out = claim_output(args, "diagnose", replace=args.force)  # --out, before any work
    starts = {} if args.starts is None else {"starts": args.starts}  # None: diagnose's STARTS
    diag = diagnose(pair, folder, budget, **starts, seed=args.seed, progress=True, delivered=args.delivered,
                    device=args.device)
    fitted = fitted_pair(folder, diag, device=args.device)
    out.create()
    atomic_write_json(out.path / "diagnosis.json", diag)
    prov = {"source": "diagnose", "levels_sha256": diag["design_levels_sha256"], "design": str(folder),
            "measured": {k: v for k, v in (pair.provenance or {}).items() if k in ("source", "recordings_sha256")}}
    save_psf_pair(fitted, out.path / "psf_pair_fitted.npz", provenance=prov)
    write_report(out.path / "diagnosis.html", diag, pair, fitted)
    fit = diag["fit"]
    print(f"fitted in {fit['seconds']:.0f} s ({fit['parts']} parts computed, {len(fit['starts'])} starts); PSF metric "
          f"{diag['psf_metric']['as_measured']:.3f} as measured, {diag['psf_metric']['nominal']:.3f} error-free")
    for a in diag["actions"]:
        print(f"- {a}")
    print(f"wrote {out.path / 'diagnosis.json'}, psf_pair_fitted.npz, diagnosis.html")
    return 0

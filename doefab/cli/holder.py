"""``doefab holder``: the parametric DOE holder (see holder_cad; lengths in mm).

Example: doefab holder --out out/holder --set thread_diameter_mm=52 (the pitch and the flange follow from it)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

from holder_cad.params import HolderError, HolderParams

from doefab.cli._args import DefaultsHelp


def register(sub) -> None:
    p = sub.add_parser("holder", help="build and check the 3D-printable DOE holder",
                       description=__doc__, formatter_class=DefaultsHelp)
    add_arguments(p)
    p.set_defaults(func=run)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, help="output folder (holder.stl/.3mf/.step, coupon.stl, renders, holder.json)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a parameter (lengths in mm), e.g. --set die_width_mm=14 --set mount=slip; "
                        "names: " + ", ".join(f.name for f in dataclasses.fields(HolderParams)))
    p.add_argument("--no-step", action="store_true", help="skip the cadquery STEP export (mesh path only)")
    p.add_argument("--no-renders", action="store_true", help="skip the PNG renders")
    p.add_argument("--force", action="store_true", help="replace an earlier holder output in OUT")


def params_from_sets(sets: list[str]) -> HolderParams:
    """HolderParams from ``--set NAME=VALUE`` items; numbers must be finite (lengths in mm)."""
    import math

    fields = {f.name: f for f in dataclasses.fields(HolderParams)}
    values = {}
    for item in sets:
        if "=" not in item:
            raise HolderError(f"--set expects NAME=VALUE, got {item!r}")
        name, raw = item.split("=", 1)
        if name not in fields:
            raise HolderError(f"unknown holder parameter {name!r} in --set; known: {', '.join(fields)}")
        if name in values:
            raise HolderError(f"--set {name} is given twice: give each parameter once")
        default = getattr(HolderParams(), name)
        unit = " in mm" if name.endswith("_mm") else ""
        try:
            v = type(default)(raw) if not isinstance(default, str) else raw
        except ValueError:
            raise HolderError(f"--set {name} expects {'an integer' if isinstance(default, int) else 'a number'}"
                              f"{unit}, got {raw!r}") from None
        if isinstance(v, float) and not math.isfinite(v):
            raise HolderError(f"--set {name} must be a finite number{unit}, got {raw!r}")
        values[name] = v
    return HolderParams(**values)


def run(args) -> int:
    from doefab.cli._output import claim_output
    from holder_cad.build import write_holder

    p = params_from_sets(args.set)
    out = claim_output(args, "holder", replace=getattr(args, "force", False),
                       keep_on_failure=lambda: (args.outdir.path / "holder.FAILED.json").is_file())
    out.create()
    report = write_holder(p, out.path, step=False if args.no_step else None, renders=not args.no_renders)
    c = report["checks"]
    for note in report["warnings"]:
        print(f"warning: {note}", file=sys.stderr)
    print(json.dumps({"checks_passed": c["passed"], "bodies": {k: {kk: v[kk] for kk in ("volume_mm3", "min_wall_mm",
                      "overhang_area_beyond_45deg_mm2")} for k, v in c["bodies"].items()},
                      "die_to_pocket_gap_mm": c.get("die_to_pocket_gap_mm"),
                      "aperture_rays_blocked": c.get("aperture_rays_blocked"),
                      "doe_to_lens_mm": report["doe_to_lens_mm"], "files": report["files"]}, indent=1))
    return 0

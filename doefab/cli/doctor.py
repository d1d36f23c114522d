"""``doefab doctor SCENE``: what the scene's camera and task imply (f-number, diffraction limit in sensor
pixels, DOE pixels across the aperture, depth of field, the task's geometry in pixels), then its sampling
conditions and numerical stiff spots, each with its margin and, where it fails, the fix (exit status 3 if any
fails), and the device torch computes on (--device, else the scene's device key). A new design's run time is
measured from a few of its own steps (--no-timing skips it); nothing is designed or trained."""

from __future__ import annotations

from doefab.cli._args import add_device_arg


def register(sub) -> None:
    p = sub.add_parser("doctor", help="check a scene's numbers and sampling before running it", description=__doc__)
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("--out", default=None, help="also write the checks as JSON to this file")
    p.add_argument("--no-precision", action="store_true", help="skip the float32 vs float64 PSF computation")
    p.add_argument("--no-timing", action="store_true", help="skip timing a new design's first steps (its run time)")
    add_device_arg(p, scene=True)
    p.set_defaults(func=run)


def run(args) -> int:
    from doefab._devices import using_device
    from doefab.pipeline.scene import load_scene

    if args.out is not None:
        check_report_file(args.out)  # before any work
    scene = load_scene(args.scene)  # its device key checked with every other key
    with using_device(scene.device if args.device is None else None, "scene"):
        return _diagnose(args, scene)


def _diagnose(args, scene) -> int:
    from doefab._devices import describe_device
    from doefab.errors import CheckFailed
    from doefab.io import atomic_write_json
    from doefab.pipeline.doctor import design_time_fact, diagnose, explain
    from doefab.pipeline.system import resolve

    res = resolve(scene)
    facts = explain(res, scene) + ([] if args.no_timing or "design" not in scene.stages else [design_time_fact(res)])
    width = max(len(f["quantity"]) for f in facts)
    print(f"{args.scene}: the system")
    for f in facts:
        print(f"  {f['quantity']:<{width}}  {f['value']:>8.4g} {f['unit']:<10} {f['meaning']}")
    for note in res.warnings:
        print(f"warning: {note}")
    print(f"device: {describe_device()}")
    print("checks")
    rows = diagnose(scene, precision_check=not args.no_precision, res=res)
    for r in rows:
        val = f"{r['value']:.4g}" if isinstance(r["value"], float) else str(r["value"])
        print(f"{'ok  ' if r['ok'] else 'FAIL'} {r['check']}: {val} {r['unit']} (limit {r['bound']} {r['limit']:.4g}, margin "
              f"{r['margin']:.3g})" + (f" — fix: {r['fix']}" if r["fix"] else ""))
    if args.out:
        atomic_write_json(args.out, {"written_by": WRITTEN_BY, "scene": str(args.scene), "system": facts,
                                     "warnings": res.warnings, "checks": rows})  # strict JSON: margins may be ∞
    bad = [r["check"] for r in rows if not r["ok"]]
    if bad:
        raise CheckFailed(f"{len(bad)} check(s) fail: {'; '.join(bad)}")
    print(f"{args.scene}: every check passes")
    return 0


WRITTEN_BY = "doefab doctor"


def check_report_file(out: str) -> None:
    """``--out`` names a JSON file doctor may write: not empty, not a folder, not a file of the user's (an
    existing file is replaced only when it is an earlier doctor report)."""
    import json
    from pathlib import Path

    from doefab.errors import DoefabError

    if not str(out).strip():
        raise DoefabError("--out is empty: give a file path (e.g. --out doctor.json)")
    p = Path(out)
    if p.is_dir():
        raise DoefabError(f"--out {p} is a folder: give a file path (e.g. {p / 'doctor.json'})")
    if p.exists():
        try:
            ours = json.loads(p.read_text()).get("written_by") == WRITTEN_BY
        except (OSError, ValueError, AttributeError):
            ours = False
        if not ours:
            raise DoefabError(f"--out {p} exists and is not an earlier doefab doctor report: doefab never replaces "
                              f"a file of yours; choose another name")
    if not p.parent.is_dir():
        raise DoefabError(f"--out {p}: its folder {p.parent} does not exist; create it first")

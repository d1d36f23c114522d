"""Build, check and write the holder: STL/3MF (mesh path), STEP (cadquery path, when installed), renders, JSON."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from holder_cad import derive
from holder_cad.checks import run_checks
from holder_cad.mesh import build_manifold, to_trimesh
from doefab.errors import CheckFailed
from holder_cad.params import HolderError, HolderParams
from holder_cad.recipe import base_body, cartridge_body, coupon_bodies

__all__ = ["build_parts", "assembly", "write_holder", "HolderCheckError"]


class HolderCheckError(HolderError, CheckFailed):
    """A built holder failed one of its checks (the message names the failing quantities; the full report is
    ``holder.FAILED.json``). No printable file is written for a part that fails."""


def build_parts(p: HolderParams) -> dict:
    """Manifolds of the base and the cartridge, each in its print orientation (on the bed at z = 0)."""
    return {"base": build_manifold(base_body(p), p.segments), "cartridge": build_manifold(cartridge_body(p), p.segments)}


def assembly(parts: dict, p: HolderParams) -> list:
    """Both bodies in use position: lens side at z = 0, optical axis = z, scene toward +z."""
    base, cart = parts["base"], parts["cartridge"]
    if p.mount == "thread":
        base_use = base
        seat = p.base_height_mm
    else:  # the slip-fit base prints plate-down: flip it so the plate's lens face is at z = 0
        base_use = base.rotate((180.0, 0.0, 0.0)).translate((0.0, 0.0, p.flange_height_mm))
        seat = p.flange_height_mm
    cart_use = cart.rotate((180.0, 0.0, 0.0)).translate((0.0, 0.0, seat + p.cartridge_flange_mm))
    return [base_use, cart_use]


def _layout_for_print(manifolds: list, gap: float = 5.0) -> list:
    """Place bodies side by side along x on the bed."""
    out, x = [], 0.0
    for m in manifolds:
        b = m.bounding_box()
        out.append(m.translate((x - b[0], -0.5 * (b[1] + b[4]), -b[2])))
        x += (b[3] - b[0]) + gap
    return out


def _export_mesh(manifolds: list, path: Path, fmt: str, names: tuple[str, ...] = ()) -> None:
    """The bodies laid out for print in one file: an STL of them all; a 3MF with one object per body, named by
    ``names`` (a slicer lists and places them one by one)."""
    import trimesh

    from doefab.io import atomic_write_bytes

    meshes = [to_trimesh(m) for m in manifolds]
    if fmt == "3mf" and names:
        scene = trimesh.Scene()
        for name, mesh in zip(names, meshes, strict=True):
            scene.add_geometry(mesh, geom_name=name, node_name=name)
        atomic_write_bytes(path, scene.export(file_type=fmt))
        return
    atomic_write_bytes(path, trimesh.util.concatenate(meshes).export(file_type=fmt))


def _write_meshes(parts: dict, coupon: dict, out: Path, report: dict) -> None:
    """The printable meshes laid out on the bed (holder.stl, holder.3mf, coupon.stl), the layout's footprint in
    ``report`` and a warning where it is wider than a common bed."""
    printed = _layout_for_print([parts["base"], parts["cartridge"]])
    boxes = np.array([m.bounding_box() for m in printed])  # (xmin, ymin, zmin, xmax, ymax, zmax) per body
    foot = report["print_footprint_mm"] = [round(float(v), 2) for v in boxes[:, 3:].max(0) - boxes[:, :3].min(0)]
    if max(foot[:2]) > derive.COMMON_BED_MM:
        report["warnings"].append(f"holder.stl lays the base and the cartridge side by side over {foot[0]:g} × "
                                  f"{foot[1]:g} mm, more than a common {derive.COMMON_BED_MM:g} mm bed: print them "
                                  f"one at a time (holder.3mf holds each as its own object)")
    _export_mesh(printed, out / "holder.stl", "stl")
    _export_mesh(printed, out / "holder.3mf", "3mf", ("base", "cartridge"))
    _export_mesh(_layout_for_print(list(coupon.values())), out / "coupon.stl", "stl")
    report["files"] = ["holder.stl", "holder.3mf", "coupon.stl"]


def write_holder(p: HolderParams, out_dir: str | Path, step: bool | None = None, renders: bool = True) -> dict:
    """Build and check the holder; only a part that passes every check gets printable files.

    A failed check raises HolderCheckError naming the failing quantities, after writing the full report as
    ``holder.FAILED.json`` (and no STL/3MF/STEP, so nothing printable looks finished).
    """
    from doefab.errors import DoefabError
    from doefab.io import MARKER, atomic_write_json, mark_folder, read_marker

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DoefabError(f"{out} is a file: give a folder for the holder's files")
    marker = read_marker(out)
    holders = marker is not None and (marker.get("kind") == "holder" or
                                      (marker.get("kind") == "run stage" and marker.get("stage") == "holder"))
    if out.is_dir() and any(out.iterdir()) and not holders:
        what = (f"a doefab {marker.get('kind')} output" if marker is not None else
                f"files and no doefab ownership marker ({MARKER})")
        raise DoefabError(f"{out} holds {what}: the holder's files are written only into a new, empty or doefab "
                          f"holder folder; choose another")
    out.mkdir(parents=True, exist_ok=True)
    if read_marker(out) is None:
        mark_folder(out, "holder")
    t0 = time.perf_counter()
    parts = build_parts(p)
    asm = assembly(parts, p)
    checks = run_checks(parts, asm, p, expected_bodies=2)
    t_mesh = time.perf_counter() - t0
    coupon = {b.name: build_manifold(b, p.segments) for b in coupon_bodies(p)}
    coupon_checks = run_checks(coupon, [], p, expected_bodies=2)
    report = {"units": "mm", "parameters": p.to_dict(), "derived": list(p.derived), "warnings": p.warnings,
              "checks": checks, "coupon_checks": coupon_checks,
              "doe_to_lens_mm": checks["doe_to_lens_mm"], "mesh_seconds": round(t_mesh, 3), "files": []}
    if not (checks["passed"] and coupon_checks["passed"]):
        (out / "holder.json").unlink(missing_ok=True)
        atomic_write_json(out / "holder.FAILED.json", report)
        why = checks["failing"] + [f"coupon {w}" for w in coupon_checks["failing"]]
        raise HolderCheckError(f"the holder fails its checks: {'; '.join(why) or 'see the report'} (full report: "
                               f"{out / 'holder.FAILED.json'}; no printable file was written)")
    (out / "holder.FAILED.json").unlink(missing_ok=True)
    _write_meshes(parts, coupon, out, report)
    if step is None:
        try:
            import cadquery  # noqa: F401

            step = True
        except ImportError:
            step = False
    if step:
        from holder_cad.brep import build_brep, export_step

        t1 = time.perf_counter()
        solids = build_brep(p)
        report["brep_vs_mesh"] = {name: {"volume_mm3": round(s.Volume(), 3),
                                         "volume_rel_diff": abs(s.Volume() - parts[name].volume()) / parts[name].volume(),
                                         "bbox_max_diff_mm": float(np.max(np.abs(
                                             np.array(_bbox(s)) - np.array(parts[name].bounding_box()))))}
                                  for name, s in solids.items()}
        ok = all(v["volume_rel_diff"] <= 0.01 and v["bbox_max_diff_mm"] <= 0.05 for v in report["brep_vs_mesh"].values())
        checks["brep_agrees"] = ok
        if not ok:
            for f in report["files"]:
                (out / f).unlink(missing_ok=True)
            report["files"] = []
            atomic_write_json(out / "holder.FAILED.json", report)
            raise HolderCheckError(f"the cadquery B-rep and the mesh disagree (volume or bounding box): "
                                   f"{report['brep_vs_mesh']}; no printable file was kept")
        export_step(solids, out / "holder.step")
        report["files"].append("holder.step")
        report["step_seconds"] = round(time.perf_counter() - t1, 3)
    if renders:
        report["files"] += _renders(p, out)
    atomic_write_json(out / "holder.json", report)
    return report


def _renders(p: HolderParams, out: Path) -> list[str]:
    """The assembly's PNG views (``render.render_views``) of a coarse build (48 facets round: flat shading)."""
    from holder_cad.render import render_views

    coarse = p.replace(segments=48)
    return render_views(coarse, assembly(build_parts(coarse), coarse), out)


def _bbox(solid) -> tuple:
    bb = solid.BoundingBox()
    return (bb.xmin, bb.ymin, bb.zmin, bb.xmax, bb.ymax, bb.zmax)

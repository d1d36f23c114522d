"""Checks on the built meshes (all reported in holder.json; any failure fails the command).

watertight and a valid volume (trimesh ``is_volume``), the declared number of bodies, manifold3d status
NoError, minimum wall thickness measured on the mesh by ray casting (thread teeth excluded), die-to-pocket
gap from a section at mid-pocket height, clear aperture unobstructed (axial rays through the aperture disk, and
rays at the field's half-angle through it, hit nothing in the assembly), and the overhang area beyond 45° in print
orientation.
"""

from __future__ import annotations

import math

import numpy as np

from holder_cad.params import HolderParams, fit_bounds
from holder_cad.recipe import die_outline, thread_points

__all__ = ["wall_thickness", "overhang_area", "facet_sag_mm", "facet_tolerance_mm", "pocket_gap", "pocket_wall",
           "aperture_clear",
           "run_checks"]

OVERHANG_LIMIT_DEG = 45.0
ANGLE_TOLERANCE_DEG = 0.5
OVERHANG_TOLERANCE_MM2 = 1e-3  # boolean slivers (~1e-7 mm²) are not printable overhangs
WALL_TOLERANCE_MM = 0.01  # facets of the default 128-gon sit up to 0.009 mm inside a 28.5 mm circle
# the most the checks allow for the facets' error, under a tenth of a 0.4 mm line; a coarser mesh fails (its walls
# are that much thinner in the STL): more segments fix it
FACET_TOLERANCE_MAX_MM = 0.03


def facet_sag_mm(manifold, segments: int) -> float:
    """How far the facets of a ``segments``-gon sit inside the part's largest circle (mm): R (1 − cos(π / n)),
    R the part's largest distance from the axis in x or y (0.0235 mm for a 78 mm radius at 128 facets). A wall
    measured on the mesh may fall short of the designed one by this much, and a downward face narrower than it
    (where two faceted circles of nearly one radius meet) is an artefact of the facets, not a printable overhang.

    Example: ``facet_sag_mm(manifold3d.Manifold.cylinder(2, 78, circular_segments=128), 128)`` → 0.0235."""
    x0, y0, _, x1, y1, _ = manifold.bounding_box()
    return max(abs(x0), abs(y0), abs(x1), abs(y1)) * (1.0 - math.cos(math.pi / int(segments)))


def facet_tolerance_mm(sag_mm: float) -> float:
    """What the wall and overhang checks allow for the facets' error (mm): ``sag_mm`` (``facet_sag_mm``), at least
    ``WALL_TOLERANCE_MM`` and at most ``FACET_TOLERANCE_MAX_MM``."""
    return min(max(WALL_TOLERANCE_MM, sag_mm), FACET_TOLERANCE_MAX_MM)


def wall_thickness(manifold, exclude=None, samples: int = 2000, seed: int = 0, where: list | None = None) -> float:
    """Smallest material thickness (mm) along inward face normals, over area-weighted sample faces.

    Args:
        exclude: optional function (centroids (N, 3)) -> bool mask of faces to skip (e.g. thread teeth).
        where: if given, receives the (x, y, z) of the thinnest sample.
    """
    mesh = manifold.to_mesh()
    v = np.asarray(mesh.vert_properties, np.float64)[:, :3]
    f = np.asarray(mesh.tri_verts, np.int64)
    tri = v[f]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1) / 2
    ok = area > 1e-9
    normal = np.zeros_like(cross)
    normal[ok] = cross[ok] / (2 * area[ok])[:, None]
    cent = tri.mean(axis=1)
    if exclude is not None:
        ok &= ~exclude(cent)
    idx = np.flatnonzero(ok)
    rng = np.random.default_rng(seed)
    # half the samples by area (large walls), half by count (small features have many small facets)
    by_area = rng.choice(idx, size=min(samples // 2, idx.size), replace=False, p=area[idx] / area[idx].sum())
    by_count = rng.choice(idx, size=min(samples // 2, idx.size), replace=False)
    pick = np.unique(np.concatenate([by_area, by_count]))
    eps = 1e-4
    best = math.inf
    for i in pick:
        o = cent[i] - eps * normal[i]
        hits = manifold.ray_cast(tuple(o), tuple(o - 100.0 * normal[i]))
        if hits and hits[0].distance * 100.0 + eps < best:
            best = hits[0].distance * 100.0 + eps
            if where is not None:
                where[:] = [round(float(x), 3) for x in cent[i]]
    return best


def overhang_area(manifold, limit_deg: float = OVERHANG_LIMIT_DEG, sliver_mm: float = 0.0) -> float:
    """Area (mm²) of downward faces steeper than ``limit_deg`` from vertical, excluding the bed (z = min) and
    connected regions of such faces narrower than ``sliver_mm`` (twice their area over their perimeter: a strip's
    width; where two faceted circles of nearly one radius meet, a few µm)."""
    mesh = manifold.to_mesh()
    v = np.asarray(mesh.vert_properties, np.float64)[:, :3]
    tri = v[np.asarray(mesh.tri_verts, np.int64)]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1) / 2
    nz = np.divide(cross[:, 2], 2 * area, out=np.zeros_like(area), where=area > 0)
    zmin = v[:, 2].min()
    on_bed = np.all(np.abs(tri[:, :, 2] - zmin) < 1e-6, axis=1)
    steep = nz < -math.sin(math.radians(limit_deg + ANGLE_TOLERANCE_DEG))
    down = np.flatnonzero(steep & ~on_bed)
    if sliver_mm > 0 and down.size:
        down = down[_region_widths(np.asarray(mesh.tri_verts, np.int64)[down], v, area[down]) >= sliver_mm]
    return float(area[down].sum())


def _region_widths(faces: np.ndarray, v: np.ndarray, area: np.ndarray) -> np.ndarray:
    """Per face of ``faces`` (vertex indices into ``v``): the width of its connected region (faces joined by
    shared edges), twice the region's area over its perimeter (a strip's width, a disc's radius), mm."""
    import trimesh

    tm = trimesh.Trimesh(v, faces, process=False)
    label = trimesh.graph.connected_component_labels(tm.face_adjacency, node_count=len(faces))
    rim = trimesh.grouping.group_rows(tm.edges_sorted, require_count=1)  # edges of one face only: the regions' rims
    length = np.linalg.norm(np.diff(v[tm.edges_sorted[rim]], axis=1)[:, 0], axis=1)
    k = int(label.max()) + 1
    perimeter = np.bincount(label[tm.edges_face[rim]], weights=length, minlength=k)
    widths = 2 * np.bincount(label, weights=area, minlength=k) / np.maximum(perimeter, 1e-300)
    return widths[label]


def _largest_offset(clear, hi: float) -> float:
    """The largest offset in [0, ``hi``] (mm, to 2^-40 of ``hi``) for which ``clear(offset)`` holds, bisected
    (``clear`` holds at 0 and turns false once past the answer)."""
    lo = 0.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if clear(mid) else (lo, mid)
    return lo


def pocket_gap(cartridge, p: HolderParams, z_mid: float) -> float:
    """Smallest gap (mm) between the die outline and the cartridge section at height ``z_mid``."""
    from manifold3d import CrossSection

    section = cartridge.slice(z_mid)
    die = CrossSection([die_outline(p).tolist()])
    if (die ^ section).area() > 1e-9:
        return 0.0
    return _largest_offset(lambda d: (die.offset(d, _join("Miter")) ^ section).area() <= 1e-9, 5.0)


def pocket_wall(cartridge, p: HolderParams, z_mid: float) -> float:
    """Thinnest wall (mm) between the die pocket (the die outline offset by ``clearance_mm``, mitred, as built) and
    the cartridge's outside in its section at height ``z_mid``: the ray-cast wall check samples faces and can
    miss a pocket corner's nearest approach to the round outside."""
    from manifold3d import CrossSection

    polys = [np.asarray(q) for q in cartridge.slice(z_mid).to_polygons()]
    if not polys:
        return 0.0
    outer = max(polys, key=lambda q: float(np.hypot(*q.T).max()))  # the section's outer contour
    outside = CrossSection([outer.tolist()])  # filled
    pocket = CrossSection([die_outline(p).tolist()]).offset(p.clearance_mm, _join("Miter"))
    return _largest_offset(lambda d: (pocket.offset(d, _join("Round"), circular_segments=256) - outside).area() <= 1e-9,
                           float(np.hypot(*outer.T).max()))  # no wall is thicker than the radius


def _join(name):
    from manifold3d import JoinType

    return getattr(JoinType, name)


def aperture_clear(assembly_parts, radius_mm: float, rings: int = 12, angle_deg: float = 0.0, z_mm: float = 0.0,
                   azimuths: int = 8, die_mm: float = 0.0) -> int:
    """Number of rays through the aperture disk (radius_mm, in the plane z = z_mm of the use position: the DOE
    face and its chrome stop) that hit the assembly (0 = unobstructed): axial rays, or at ``angle_deg`` to the
    axis from ``azimuths`` directions round it (the light of a field point that far off axis), refracted inside
    the ``die_mm`` thick die in front of the disk (index ``DIE_INDEX_MIN``) and straight in air."""
    from holder_cad.derive import die_spread_mm

    b = [m.bounding_box() for m in assembly_parts]
    reach = max(max(x[5] for x in b) - z_mm, z_mm - min(x[2] for x in b)) + 10  # beyond the assembly both ways
    spread = die_spread_mm(die_mm, angle_deg)  # inside the die
    pts = [(0.0, 0.0)]
    for k in range(1, rings + 1):
        r = radius_mm * k / rings
        n = 6 * k
        pts += [(r * math.cos(2 * math.pi * j / n), r * math.sin(2 * math.pi * j / n)) for j in range(n)]
    t = math.radians(angle_deg)
    dirs = [(0.0, 0.0, 1.0)] if angle_deg == 0 else [
        (math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t))
        for a in (2 * math.pi * j / azimuths for j in range(azimuths))]
    hits = 0
    for x, y in pts:
        for d in dirs:
            s = reach / d[2]  # to the planes the assembly lies between
            c, r = math.hypot(d[0], d[1]) or 1.0, spread
            xb, yb, zb = x + r * d[0] / c, y + r * d[1] / c, z_mm + die_mm  # where it left the die's back
            for a, e in (((x, y, z_mm), (x - s * d[0], y - s * d[1], z_mm - reach)),  # toward the lens
                         ((xb, yb, zb), (xb + s * d[0], yb + s * d[1], zb + reach))):  # toward the scene
                hits += sum(bool(m.ray_cast(a, e)) for m in assembly_parts)
    return hits


def _thread_teeth(p: HolderParams):
    """Where the thread's teeth are (a mask over points, mm): they are not walls (0.3 mm by design)."""
    r_root, t = p.thread_root_radius_mm, p.thread_length_mm
    return lambda c: (np.hypot(c[:, 0], c[:, 1]) > r_root - 0.05) & (c[:, 2] < t + 0.05)


def run_checks(parts: dict, assembly: list, p: HolderParams, expected_bodies: int) -> dict:
    """All checks; ``parts`` maps body name -> Manifold in print orientation."""
    from holder_cad.mesh import to_trimesh

    out: dict = {"bodies": {}, "passed": True}
    n_bodies = 0
    for name, m in parts.items():
        tm = to_trimesh(m)
        comps = len(m.decompose())
        n_bodies += comps
        exclude = _thread_teeth(p) if name in ("base", "coupon_ring") and p.mount == "thread" else None
        loc: list = []
        wall = wall_thickness(m, exclude, where=loc)
        facets = min(p.segments, thread_points(p)) if p.mount == "thread" else p.segments  # the coarser polygon
        sag = facet_sag_mm(m, facets)
        tol = facet_tolerance_mm(sag)
        oh = overhang_area(m, sliver_mm=tol)
        entry = {"status": str(m.status()).split(".")[-1], "watertight": bool(tm.is_watertight),
                 "is_volume": bool(tm.is_volume), "volume_mm3": round(float(m.volume()), 3), "bodies": comps,
                 "min_wall_mm": round(wall, 3), "min_wall_at_mm": loc, "overhang_area_beyond_45deg_mm2": round(oh, 3),
                 "facet_sag_mm": round(sag, 4),
                 "bounding_box_mm": [round(float(x), 4) for x in m.bounding_box()]}
        entry["shape_ok"] = (entry["status"] == "NoError" and entry["watertight"] and entry["is_volume"]
                             and wall >= p.wall_mm - tol and oh < OVERHANG_TOLERANCE_MM2)
        entry["ok"] = entry["shape_ok"] and sag <= FACET_TOLERANCE_MAX_MM
        out["bodies"][name] = entry
        out["passed"] &= entry["ok"]
    out["total_bodies"] = n_bodies
    out["declared_bodies"] = expected_bodies
    out["passed"] &= n_bodies == expected_bodies
    if "cartridge" in parts:
        c = parts["cartridge"]
        top = c.bounding_box()[5]
        z_mid = top - p.washer_recess_mm - p.die_thickness_mm / 2
        gap = pocket_gap(c, p, z_mid)
        out["die_to_pocket_gap_mm"] = round(gap, 4)
        wall = pocket_wall(c, p, z_mid)
        out["pocket_wall_mm"] = round(wall, 4)
        if wall < p.wall_mm - facet_tolerance_mm(facet_sag_mm(c, p.segments)):  # as the wall check allows
            out["passed"] = False
            out.setdefault("fit_failures", []).append(f"pocket_wall_mm = {wall:.3f} (needs ≥ {p.wall_mm}: a smaller "
                                                      "die or a larger thread)")
        out["passed"] &= gap >= p.clearance_mm - 1e-3
        if gap < p.clearance_mm - 1e-3:
            out.setdefault("fit_failures", []).append(f"die_to_pocket_gap_mm = {gap:.3f} (needs ≥ {p.clearance_mm})")
    if assembly:
        blocked = aperture_clear(assembly, p.clear_aperture_mm / 2)
        out["aperture_rays_blocked"] = blocked
        out["passed"] &= blocked == 0
    measured = doe_face_height(assembly, p) if assembly else None
    if assembly and p.field_half_angle_deg > 0:  # the field's edge, through the DOE face (its chrome stop)
        face = measured if measured is not None else p.washer_recess_mm
        out["field_rays_blocked"] = aperture_clear(assembly, p.clear_aperture_mm / 2, 6, p.field_half_angle_deg, face,
                                                   die_mm=p.die_thickness_mm)
        out["passed"] &= out["field_rays_blocked"] == 0
    if measured is not None:
        reach = p.thread_length_mm if p.mount == "thread" else 0.0
        out["doe_face_above_lens_side_end_mm"] = round(measured, 4)
        d = p.lens_face_to_glass_mm - reach + measured
    else:
        d = p.doe_to_lens_mm
    out["doe_to_lens_mm"] = round(d, 3)
    out["fit_bounds"] = fit_bounds(p, doe_to_lens_mm=d)
    out["passed"] &= all(b["ok"] for b in out["fit_bounds"])
    out["failing"] = failing(out)
    return out


def doe_face_height(assembly_parts, p: HolderParams) -> float | None:
    """Height (mm) of the DOE face above the assembly's lens-side end (z = 0), measured on the mesh: an axial
    ray beside the aperture, inside the die pocket, meets the pocket ceiling (the die's back) first."""
    x, y = 0.0, p.die_height_mm / 2 - 0.3
    for m in assembly_parts[1:] or assembly_parts:
        hits = m.ray_cast((x, y, -50.0), (x, y, 200.0))
        if hits:
            return -50.0 + hits[0].distance * 250.0 - p.die_thickness_mm
    return None


def failing(checks: dict) -> list[str]:
    """Names (and values) of every failed check, for the one-line error."""
    out = []
    for name, b in checks.get("bodies", {}).items():
        if not b.get("shape_ok", b.get("ok", True)):
            why = [k for k, bad in (("manifold status", b["status"] != "NoError"), ("not watertight", not b["watertight"]),
                                    ("not a volume", not b["is_volume"]),
                                    (f"min wall {b['min_wall_mm']} mm", True)) if bad]
            out.append(f"{name}: {', '.join(why[:2])}; overhang {b['overhang_area_beyond_45deg_mm2']} mm²")
        if b.get("facet_sag_mm", 0.0) > FACET_TOLERANCE_MAX_MM:
            out.append(f"{name}'s facets sit {b['facet_sag_mm']} mm inside its largest circle, its walls up to as "
                       f"much thinner than designed (at most {FACET_TOLERANCE_MAX_MM} mm allowed): raise segments")
    if checks.get("total_bodies") != checks.get("declared_bodies"):
        out.append(f"bodies {checks.get('total_bodies')} (declared {checks.get('declared_bodies')})")
    out += checks.get("fit_failures", [])
    if checks.get("aperture_rays_blocked"):
        out.append(f"aperture_rays_blocked = {checks['aperture_rays_blocked']}")
    if checks.get("field_rays_blocked"):
        out.append(f"field_rays_blocked = {checks['field_rays_blocked']} (at the field's half-angle)")
    for b in checks.get("fit_bounds", []):
        if not b["ok"]:
            out.append(f"{b['quantity']} = {b['value']:.3g} {b['unit']} (allowed {b['min']:g}–{b['max']:g})")
    return out

"""Everything in a mask layout besides the etched pixels, checked against what the manifest says is there.

From the manifest's die (``die_m``), clear aperture (``clear_aperture_diameter_m``), critical dimension (the etch
layers' ``critical_dimension_nm``), alignment chain and vertex cap, :func:`expected_layout` draws the chrome plate,
every plate's keys, windows, verniers and CD ladder and the die outline again with the code that drew them on
export (:func:`doefab.fabrication.marks.mark_layout`), and checks the manifest's key-site table against that
drawing. :func:`layout_problems` compares each (layer, datatype) of the file with it: area the file holds beyond
the drawing is *extra*, area it lacks is *missing*. A difference counts where it is wider than
``TOLERANCE_DBU`` database units (2 nm: a vertex rounded to the 1 nm grid on either side), so a chrome aperture
moved by 200 µm, a key moved by 1 µm, a deleted mark and a rectangle added anywhere all fail.
:func:`stray_layers` names every (layer, datatype) that the set does not hold, :func:`unlisted_layers` every
one whose layer the manifest's ``layers`` and ``other_layers`` do not list (the fab reads a layer's purpose there).
"""

from __future__ import annotations

import json

import numpy as np

from doefab.errors import CheckFailed, DoefabError
from doefab.fabrication.layers import (CHROME_LAYER, KEY_LAYER, LAYER_PURPOSES, OUTLINE_LAYER, VERNIER_LAYER,
                                      etch_bit)
from doefab.fabrication.manifest import drawn_before_3
from doefab.fabrication.marks import MarkSpec, key_site, mark_layout, vernier_record

__all__ = ["TOLERANCE_DBU", "DBU_NM", "expected_layout", "check_layout", "layout_problems", "stray_layers",
           "unlisted_layers", "listed_layers", "layer_name"]

DBU_NM = 1  # the layout's database unit (GDSWriter, manifest ``database_unit_m``)
# a difference between the file and the manifest's drawing counts where it is wider than this (database units)
TOLERANCE_DBU = 2
_FIX = "the file no longer holds what its manifest describes (edited or damaged): export the set again from its design"


def layer_name(layer: int, datatype: int) -> str:
    """What a (layer, datatype) of a mask set holds, in words."""
    if (layer, datatype) == (CHROME_LAYER, 0):
        return "chrome aperture, plate 0"
    if layer == KEY_LAYER:
        return f"alignment keys and windows, plate {datatype}"
    if layer == VERNIER_LAYER:
        return f"verniers and CD ladder, plate {datatype}"
    if (layer, datatype) == (OUTLINE_LAYER, 0):
        return "die outline"
    try:
        return f"etch, bit {etch_bit(layer)}" if datatype == 0 else "not a layer of the set"
    except ValueError:
        return "not a layer of the set"


def _need(ok: bool, key: str, what: str) -> None:
    if not ok:
        raise CheckFailed(f"manifest.json: {key} {what}: the marks cannot be checked; export the set again")


def _spec(man: dict, n_masks: int) -> tuple[MarkSpec, dict[int, int]]:
    """The mark geometry's inputs from the manifest (each field checked), and plate → the plate it aligns to."""
    die, ap = man.get("die_m"), man.get("clear_aperture_diameter_m")
    for key, v in (("die_m", die), ("clear_aperture_diameter_m", ap)):
        _need(not isinstance(v, bool) and isinstance(v, (int, float)) and 1e-4 <= v <= 0.3, key,
              f"= {v!r} is not a length in metres (0.1 mm – 300 mm)")
    cds = {L.get("critical_dimension_nm") for L in man["layers"] if L.get("purpose") == "etch"}
    cd = next(iter(cds)) if len(cds) == 1 else None
    _need(isinstance(cd, int) and not isinstance(cd, bool) and 100 <= cd <= 1_000_000,
          "layers[].critical_dimension_nm", f"of the etch layers ({sorted(map(repr, cds))}) is not one CD in nm")
    chain = man.get("alignment_chain")
    plates = [str(p) for p in range(1, n_masks + 1)]
    _need(isinstance(chain, dict) and sorted(chain) == sorted(plates)
          and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= n_masks and str(v) != k
                  for k, v in chain.items()),
          "alignment_chain", f"= {chain!r} does not map each etch plate {', '.join(plates)} to another plate")
    chamfer = man.get("die_chamfer_m", 0.0)  # a set written before the die was keyed: a square outline
    _need(not isinstance(chamfer, bool) and isinstance(chamfer, (int, float)) and 0 <= chamfer < die / 2,
          "die_chamfer_m", f"= {chamfer!r} is not a length in metres below half the die")
    margin = man.get("mark_clear_margin_m", 0.0)  # a set written before the marks had clear fields: none
    _need(not isinstance(margin, bool) and isinstance(margin, (int, float)) and 0 <= margin <= 1e-3,
          "mark_clear_margin_m", f"= {margin!r} is not a length in metres up to 1 mm")
    legacy = drawn_before_3(man)
    tones = {L.get("resist_tone") for L in man["layers"] if L.get("purpose") == "etch"}
    tone = next(iter(tones)) if len(tones) == 1 else None
    _need(legacy or tone in ("positive", "negative"), "layers[].resist_tone",
          f"of the etch layers ({sorted(map(repr, tones))}) is not one tone, positive or negative")
    spec = MarkSpec(die_nm=int(round(die * 1e9)), aperture_radius_nm=int(round(ap / 2 * 1e9)), cd_nm=cd,
                    chamfer_nm=int(round(chamfer * 1e9)), coded_sign=1 if man.get("mirrored_x") else -1,
                    clear_margin_nm=int(round(margin * 1e9)), windows=legacy or tone == "positive",
                    legacy=legacy)
    return spec, {int(k): v for k, v in chain.items()}


def _check_key_sites(man: dict, spec: MarkSpec, n_masks: int) -> None:
    sites = man.get("key_sites_m")
    _need(isinstance(sites, dict), "key_sites_m", "is missing")
    for p in range(n_masks + 1):
        got, want = sites.get(str(p)), key_site(spec, p)
        try:
            same = [(round(x * 1e9), round(y * 1e9)) for x, y in got] == want
        except (TypeError, ValueError):
            same = False
        if not same:
            raise CheckFailed(f"manifest.json: key_sites_m[{str(p)!r}] = {got!r} but the keys of plate {p} on a "
                              f"{spec.die_nm / 1e6:g} mm die sit at "
                              f"{[[x * 1e-9, y * 1e-9] for x, y in want]} m: the fab would look for them in the "
                              f"wrong place; export the set again")


def expected_layout(man: dict, n_masks: int) -> dict[tuple[int, int], list[np.ndarray]]:
    """(layer, datatype) → the polygons (integer vertices, nm) the manifest says the layout holds besides the etch
    layers; CheckFailed naming a manifest field that cannot be drawn or disagrees with the drawing."""
    spec, align_to = _spec(man, n_masks)
    _check_key_sites(man, spec, n_masks)
    if not spec.legacy and man.get("verniers") != vernier_record(spec.die_nm, spec.cd_nm, align_to):
        raise CheckFailed("manifest.json: verniers does not describe the verniers the set draws (sites, scales): the "
                          "fab would read them wrongly; export the set again")
    try:
        pieces = mark_layout(spec, align_to, int(man["vertex_cap"]), CHROME_LAYER)
    except DoefabError as exc:
        raise CheckFailed(f"manifest.json: the marks it describes do not fit its die ({exc})") from None
    out: dict[tuple[int, int], list[np.ndarray]] = {}
    for points, layer, datatype in pieces:
        out.setdefault((layer, datatype), []).append(points)
    return out


def _where(polys: list) -> str:
    (x0, y0), (x1, y1) = max(polys, key=lambda p: p.area()).bounding_box()
    return f"around ({(x0 + x1) / 2e3:.1f}, {(y0 + y1) / 2e3:.1f}) µm"


def _beyond(a: list, b: list) -> tuple[float, str | None]:
    """Area (µm²) of polygons ``a`` outside ``b``, and where its largest part wider than the tolerance lies
    (None when every part is a sliver within the tolerance)."""
    import gdstk

    diff = gdstk.boolean(a, b, "not", precision=1e-3)
    if not diff:
        return 0.0, None
    core = gdstk.offset(diff, -TOLERANCE_DBU * DBU_NM / 2, join="miter", precision=1e-3)
    return sum(p.area() for p in diff) / 1e6, (_where(core) if core else None)


def layout_problems(found: dict[tuple[int, int], list[np.ndarray]],
                    expected: dict[tuple[int, int], list[np.ndarray]]) -> tuple[list[str], dict]:
    """Each expected (layer, datatype) of the file (``found``: vertices in nm) against the manifest's drawing:
    the problems (one line per layer that differs beyond the tolerance, naming it and where) and a report."""
    import gdstk

    problems, report = [], {}
    for key, want in expected.items():
        got = [gdstk.Polygon(p.astype(float)) for p in found.get(key, [])]
        ref = [gdstk.Polygon(p.astype(float)) for p in want]
        extra, extra_at = _beyond(got, ref)
        missing, missing_at = _beyond(ref, got)
        report[f"{key[0]}/{key[1]}"] = {"polygons": len(got), "extra_um2": round(extra, 3),
                                        "missing_um2": round(missing, 3)}
        what = [f"{area:.1f} µm² {kind} {at}" for area, kind, at in
                ((extra, "the manifest does not place there", extra_at),
                 (missing, "missing that the manifest places", missing_at)) if at]
        if what:
            problems.append(f"layer {key[0]}/{key[1]} ({layer_name(*key)}): {'; '.join(what)}")
    return problems, report


def stray_layers(found: dict[tuple[int, int], list[np.ndarray]], allowed: set) -> list[str]:
    """One line per (layer, datatype) of ``found`` that is not in ``allowed`` (stray geometry), saying where."""
    import gdstk

    out = []
    for key in sorted(set(found) - set(allowed)):
        polys = [gdstk.Polygon(p.astype(float)) for p in found[key]]
        out.append(f"layer {key[0]}/{key[1]}: {len(polys)} polygon(s) {_where(polys)} on a layer the manifest does "
                   f"not list (the set holds {', '.join(f'{a}/{b}' for a, b in sorted(allowed))})")
    return out


def listed_layers(man: dict) -> set:
    """The layer numbers the manifest's ``layers`` and ``other_layers`` list (integers, as verification checks)."""
    return {L.get("layer") for key in ("layers", "other_layers") for L in man[key]}


def unlisted_layers(found: dict[tuple[int, int], list[np.ndarray]], listed: set) -> list[str]:
    """One line per (layer, datatype) of ``found`` whose layer is not in ``listed`` (the manifest's layer numbers):
    the fab would not know what it is; the fix names the entry to add where it is a marks or outline layer."""
    out = []
    for layer, datatype in sorted(key for key in found if key[0] not in listed):
        entry = {"layer": layer, "purpose": LAYER_PURPOSES.get(layer)}
        fix = (f"add {json.dumps(entry, ensure_ascii=False)} to its other_layers, or export the set again"
               if entry["purpose"] and layer != CHROME_LAYER else "export the set again")
        out.append(f"layer {layer}/{datatype} ({layer_name(layer, datatype)}): {len(found[(layer, datatype)])} "
                   f"polygon(s) on a layer manifest.json does not list in layers or other_layers (it lists "
                   f"{', '.join(map(str, sorted(listed)))}): {fix}")
    return out


def check_layout(found: dict, expected: dict, allowed: set, listed: set) -> dict:
    """CheckFailed naming every stray layer (not in ``allowed``: the (layer, datatype) pairs the set holds), every
    layer the manifest does not list (``listed``: its layer numbers) and every layer that differs from the
    manifest's drawing; else the per-layer report."""
    problems, report = layout_problems(found, expected)
    problems = stray_layers(found, allowed) + unlisted_layers(
        {k: v for k, v in found.items() if k in allowed}, listed) + problems
    if problems:
        raise CheckFailed(f"{len(problems)} layer(s) differ from what manifest.json describes (tolerance "
                          f"{TOLERANCE_DBU * DBU_NM} nm): {' | '.join(problems)} — {_FIX}")
    return {"tolerance_nm": TOLERANCE_DBU * DBU_NM, "layers": report}

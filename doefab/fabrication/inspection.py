"""What a fab engineer inspects beside the geometry: the width/space report of each etch layer (features and spaces
below the critical dimension, isolated single pixels, pixels that touch only at a corner; ``layer_widths`` refuses
a CD the map cannot be written at), pixels the map would etch in bare glass outside the clear aperture
(``check_marks_clear``), and the PNG previews of each etch layer and the composite, with a scale bar."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.fabrication.bitplanes import bit_plane
from doefab.fabrication.layers import etch_layer
from doefab.fabrication.process import mask_count

__all__ = ["width_space_report", "layer_widths", "check_marks_clear", "preview_names", "write_previews"]


def width_space_report(plane: np.ndarray, cd_px: int, pitch_m: float, origin_m: tuple[float, float],
                       max_locations: int = 10) -> dict:
    """Features (etched) and spaces (unetched) narrower than ``cd_px`` pixels along a row or a column, isolated
    single pixels, and corner contacts: 2 × 2 pixel blocks whose etched pixels touch only at a corner (a
    checkerboard pair), where a Euclidean width/space check finds a zero width or space (the corner may print
    pinched or bridged), with the first ``max_locations`` of each in µm."""

    def narrow(mask):
        bad = np.zeros_like(mask)
        for axis in (0, 1):
            m = np.moveaxis(mask, axis, 1)
            padded = np.pad(m, ((0, 0), (1, 1)))
            d = np.diff(padded.astype(np.int8), axis=1)
            r, s = np.nonzero(d == 1)
            _, e = np.nonzero(d == -1)
            short = (e - s) < cd_px
            b = np.zeros_like(m)
            for rr, ss, ee in zip(r[short], s[short], e[short]):
                b[rr, ss:ee] = True
            bad |= np.moveaxis(b, 1, axis)
        return bad

    p = plane.astype(bool)
    pad = np.pad(p, 1, constant_values=False)
    same = (pad[:-2, 1:-1] == p).astype(np.int8) + (pad[2:, 1:-1] == p) + (pad[1:-1, :-2] == p) + (pad[1:-1, 2:] == p)
    isolated = p & (same == 0)
    rows, cols = np.nonzero(isolated)
    locs = [[round(origin_m[0] * 1e6 + (c + 0.5) * pitch_m * 1e6, 3), round(origin_m[1] * 1e6 - (r + 0.5) * pitch_m * 1e6, 3)]
            for r, c in zip(rows[:max_locations], cols[:max_locations])]
    out = {"isolated_single_pixels": int(isolated.sum()), "isolated_locations_um": locs}
    a, b, c, d = p[:-1, :-1], p[:-1, 1:], p[1:, :-1], p[1:, 1:]  # each 2 × 2 block's four pixels
    corner = (a & d & ~b & ~c) | (b & c & ~a & ~d)
    rows, cols = np.nonzero(corner)  # the shared corner: right of and below the block's first pixel
    out["corner_contacts"] = int(corner.sum())
    out["corner_locations_um"] = [[round(origin_m[0] * 1e6 + (j + 1) * pitch_m * 1e6, 3),
                                   round(origin_m[1] * 1e6 - (i + 1) * pitch_m * 1e6, 3)]
                                  for i, j in zip(rows[:max_locations], cols[:max_locations])]
    if cd_px > 1:
        out["features_below_cd_px"] = int(narrow(p).sum())
        out["spaces_below_cd_px"] = int(narrow(~p).sum())
    else:
        out["features_below_cd_px"] = 0
        out["spaces_below_cd_px"] = 0
    return out


def layer_widths(layout: np.ndarray, n_levels: int, cd_nm: int, pitch_nm: int, origin_nm: tuple) -> dict:
    """Each etch layer's width/space report (``width_space_report``); a CD wider than the pixel pitch that
    the level map's features or spaces fall below is refused (the plates would carry what the stated CD cannot
    write)."""
    cd_px = max(1, int(math.ceil(cd_nm / pitch_nm - 1e-9)))
    out = {str(etch_layer(b)): width_space_report(bit_plane(layout, b, n_levels), cd_px, pitch_nm * 1e-9,
                                                  (origin_nm[0] * 1e-9, origin_nm[1] * 1e-9))
           for b in range(mask_count(n_levels))}
    narrow = {k: r["features_below_cd_px"] + r["spaces_below_cd_px"] for k, r in out.items()}
    if any(narrow.values()):
        worst = max(narrow, key=narrow.get)
        raise DoefabError(f"critical dimension {cd_nm / 1e3:g} µm is wider than the {pitch_nm / 1e3:g} µm pixel "
                          f"pitch and the level map has features or spaces narrower than it (layer {worst}: "
                          f"{narrow[worst]} pixels): the plates would carry what that CD cannot write; give a CD of "
                          f"at most the pitch (cd_m), or a design on a DOE pitch of at least the CD")
    return out


def check_marks_clear(layout: np.ndarray, n_levels: int, fields: list, pitch_nm: int, origin_nm: tuple) -> None:
    """Refuse a level map that etches pixels inside ``fields``, rectangles of bare glass outside the clear aperture
    (the marks' clear fields, ``marks.clear_boxes``, and the split-line slits): the etch plates would etch those
    pixels onto the marks, or beside the slits (everywhere else outside the clear aperture the chrome masks them).
    ``layout``: the level map as drawn; ``origin_nm``: the layout position of pixel (0, 0)'s top-left corner."""
    n = layout.shape[0]
    for f in fields:
        (x0, y0), (x1, y1) = f.bounding_box()
        c0, c1 = max(0, math.floor((x0 - origin_nm[0]) / pitch_nm)), min(n, math.ceil((x1 - origin_nm[0]) / pitch_nm))
        r0, r1 = max(0, math.floor((origin_nm[1] - y1) / pitch_nm)), min(n, math.ceil((origin_nm[1] - y0) / pitch_nm))
        if c0 < c1 and r0 < r1 and (layout[r0:r1, c0:c1] < n_levels - 1).any():
            raise DoefabError(f"the level map etches pixels in bare glass outside the clear aperture, round an "
                              f"alignment mark or the split-line slits, around ({(x0 + x1) / 2e6:.2f}, "
                              f"{(y0 + y1) / 2e6:.2f}) mm in the layout (where the chrome masks every other pixel): "
                              f"the etch would damage the marks; "
                              f"leave the map unetched (level {n_levels - 1}) outside the clear aperture, as doefab's "
                              f"designs do")


def preview_names(n_masks: int) -> tuple[str, ...]:
    """The preview images a finished set of ``n_masks`` etch layers holds."""
    return tuple(f"preview_layer{etch_layer(b)}.png" for b in range(n_masks)) + ("preview_composite.png",)


def write_previews(stage: Path, lv: np.ndarray, n_levels: int, pitch: float, size: int = 1000,
                   mirrored: bool = False) -> None:
    """PNG previews (Pillow; at most ``size`` px wide) of each etch layer and the composite, with a scale bar."""
    from matplotlib import colormaps
    from PIL import Image, ImageDraw

    n = lv.shape[0]
    view = ("layout view from the patterned face: the design MIRRORED in x (coded half on the right)" if mirrored
            else "layout view from the patterned face: the design as seen from the scene (not mirrored)")
    step = max(1, int(np.ceil(n / size)))
    px_m = pitch * step  # metres per preview pixel
    bar_m = 10 ** np.floor(np.log10(n * pitch / 4))  # a round length, about a quarter of the width

    def save(name: str, rgb: np.ndarray, title: str) -> None:
        img = Image.fromarray(rgb)
        pad = Image.new("RGB", (img.width, img.height + 40), "white")
        pad.paste(img, (0, 40))
        draw = ImageDraw.Draw(pad)
        draw.text((6, 4), title, fill="black")
        draw.text((6, 20), view, fill="black")
        bar_px = int(round(bar_m / px_m))
        y = pad.height - 20
        draw.rectangle([20, y, 20 + bar_px, y + 6], fill="red")
        draw.text((20, y - 14), f"{bar_m * 1e3:g} mm", fill="red")
        buf = io.BytesIO()
        pad.save(buf, format="PNG")
        (stage / name).write_bytes(buf.getvalue())

    small = lv[::step, ::step]
    for bit in range(mask_count(n_levels)):
        g = (bit_plane(small, bit, n_levels) * 255).astype(np.uint8)
        save(f"preview_layer{etch_layer(bit)}.png", np.repeat(g[..., None], 3, axis=2),
             f"layer {etch_layer(bit)}: white = etched {1 << bit}*d deep ({pitch * 1e6:g} um pixels, 1:{step})")
    rgb = (colormaps["viridis"](lv[::step, ::step] / (n_levels - 1))[..., :3] * 255).astype(np.uint8)
    save("preview_composite.png", rgb, f"composite: level 0 (deepest, dark) ... {n_levels - 1} (unetched, yellow)")

"""The mask-set page's tables and figure, read from a committed mask set (``masks/grating``).

- ``manifest-table`` renders one part of a ``manifest.json`` (``:table:`` summary, layers, other, chain, keys or
  levels) as a Markdown table.
- ``manifest-fields`` holds the page's own table of the manifest's fields and checks it against the file: a
  field the manifest has and the table does not explain, or one the table explains and the manifest lacks, is a
  warning (an error under ``-W``). ``:newer:`` names fields the exporter writes that the committed set predates
  (each must be absent from the file and written by ``doefab.fabrication.export``).
- ``write_figures`` draws the die's chrome, keys, verniers and CD ladder from the set's GDS file into
  ``docs/_generated/fab/marks.png``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

log = logging.getLogger("doefab_fab")
ROOT = Path(__file__).resolve().parents[2]
MASK_SET = ROOT / "masks" / "grating"
FIGURES = ROOT / "docs" / "_generated" / "fab"


def _manifest(path: str) -> dict:
    return json.loads((ROOT / path).read_text())


def _um(m: float) -> str:
    return f"{m * 1e6:g}"


def _mm(m: float) -> str:
    return f"{m * 1e3:g}"


def table_summary(m: dict) -> list[str]:
    mat = m["material"]
    rows = [("files", ", ".join(f"`{v}` ({k})" for k, v in m["files"].items()) + ", `manifest.json`, `README.txt`, "
             "`report.json`, `preview_*.png`"),
            ("units", f"database unit {m['database_unit_m'] * 1e9:g} nm, user unit {m['user_unit_m'] * 1e6:g} µm"),
            ("die", f"{_mm(m['die_m'])} mm × {_mm(m['die_m'])} mm, square"),
            ("pixel grid", f"{m['shape'][0]} × {m['shape'][1]} pixels at {_um(m['pitch_m'])} µm; top-left corner of "
                           f"the drawn grid (layout pixel [0, 0]"
                           + (", the level map's [0, N−1]" if m.get("mirrored_x") else "")
                           + f") at ({_mm(m['origin_m'][0])}, {_mm(m['origin_m'][1])}) mm"),
            ("clear aperture", f"{_mm(m['clear_aperture_diameter_m'])} mm diameter, centred on the die"),
            ("substrate", f"{mat['name']}, n = {m['refractive_index_at_design_wavelength']:.6f} at the design "
                          f"wavelength {m['design_wavelength_m'] * 1e9:g} nm"),
            ("levels", f"{len(m['level_to_height_nm'])}, step d = {m['level_step_nm']:g} nm "
                       f"(total relief {m['level_to_height_nm'][-1]:g} nm)"),
            ("view", f"{m['layout_view']}; mirrored in x: {'yes' if m['mirrored_x'] else 'no'}"),
            ("largest polygon", f"{m['vertex_cap']} vertices")]
    return ["| item | value |", "| --- | --- |"] + [f"| {k} | {v} |" for k, v in rows]


def table_layers(m: dict) -> list[str]:
    rows = ["| layer / datatype | plate | process step | purpose | etch depth (nm) | CD (µm) | mask polarity "
            "(for " + m["layers"][0]["resist_tone"] + " resist) | aligns to plate | its marks |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for lay in sorted(m["layers"], key=lambda x: x["process_step"]):
        depth = (f"{lay['etch_depth_nm']:g} ± {lay['etch_depth_tolerance_nm']:g}" if "etch_depth_nm" in lay else "—")
        align = "—" if lay["aligns_to_plate"] is None else str(lay["aligns_to_plate"])
        marks = ", ".join(f"{a}/{b}" for a, b in lay["marks"].values())
        rows.append(f"| {lay['layer']}/{lay['datatype']} | {lay['plate']} | {lay['process_step']} | "
                    f"{lay['purpose']}: {lay['polygons_mean']} | {depth} | {lay['critical_dimension_nm'] / 1e3:g} | "
                    f"{lay['mask_polarity']} | {align} | {marks} |")
    return rows


def table_other(m: dict) -> list[str]:
    return (["| layer | purpose |", "| --- | --- |"]
            + [f"| {x['layer']} | {x['purpose']} |" for x in m["other_layers"]])


def table_chain(m: dict) -> list[str]:
    rows = ["| plate | GDS layers on it | aligns to plate | process step |", "| --- | --- | --- | --- |"]
    steps = {str(lay["plate"]): lay["process_step"] for lay in m["layers"]}
    for plate, layers in sorted(m["plates"].items(), key=lambda kv: steps[kv[0]]):
        to = m["alignment_chain"].get(plate)
        rows.append(f"| {plate} | {', '.join(str(x) for x in layers)} | {'—' if to is None else to} | {steps[plate]} |")
    return rows


def table_keys(m: dict) -> list[str]:
    rows = ["| plate | key-site centres (x, y) in mm |", "| --- | --- |"]
    for plate, sites in m["key_sites_m"].items():
        rows.append(f"| {plate} | " + ", ".join(f"({_mm(x)}, {_mm(y)})" for x, y in sites) + " |")
    return rows


def table_levels(m: dict) -> list[str]:
    etch = {lay["bit"]: lay["layer"] for lay in m["layers"] if "bit" in lay}
    n = len(m["level_to_height_nm"])
    rows = ["| level | height above the deepest etch (nm) | etched by layers |", "| --- | --- | --- |"]
    for level, h in enumerate(m["level_to_height_nm"]):
        bits = [etch[b] for b in sorted(etch) if (n - 1 - level) >> b & 1]
        rows.append(f"| {level} | {h:g} | {', '.join(map(str, bits)) or 'none (unetched surface)'} |")
    return rows


TABLES = {"summary": table_summary, "layers": table_layers, "other": table_other, "chain": table_chain,
          "keys": table_keys, "levels": table_levels}


class _Markdown(SphinxDirective):
    def parse_markdown(self, lines: list[str]):
        from docutils import nodes

        container = nodes.container()
        self.state.nested_parse(StringList(lines, source=self.get_source_info()[0]), self.content_offset, container)
        return container.children


class ManifestTable(_Markdown):
    """One part of a mask set's manifest as a table."""

    required_arguments = 1
    option_spec = {"table": lambda arg: directives.choice(arg, tuple(TABLES))}

    def run(self):
        self.env.note_dependency(str(ROOT / self.arguments[0]))
        return self.parse_markdown(TABLES[self.options.get("table", "summary")](_manifest(self.arguments[0])))


def manifest_field_names(m: dict) -> set[str]:
    """Every field a fab reads: the top-level keys and, as ``layers[].KEY``, the keys of the layer entries."""
    names = set(m)
    for lay in m["layers"]:
        names |= {f"layers[].{k}" for k in lay}
    return names


def exporter_field_names() -> set[str]:
    """The top-level fields the mask export writes into a manifest (the keys of its ``_manifest`` record)."""
    import inspect

    from doefab.fabrication import export

    return set(re.findall(r'"(\w+)":', inspect.getsource(export._manifest)))


class ManifestFields(_Markdown):
    """The page's explanation of every manifest field, checked against the real manifest."""

    required_arguments = 1
    has_content = True
    option_spec = {"newer": directives.unchanged}

    def run(self):
        m = _manifest(self.arguments[0])
        self.env.note_dependency(str(ROOT / self.arguments[0]))
        explained = set()
        for line in self.content:
            cell = line.split("|")[1].strip() if line.strip().startswith("|") else ""
            explained |= set(re.findall(r"`([^`]+)`", cell))
        newer = set(self.options.get("newer", "").split())
        for name in sorted(newer - exporter_field_names()):
            log.warning(f":newer: names {name!r}, which the mask export does not write", location=self.get_location())
        for name in sorted(newer & manifest_field_names(m)):
            log.warning(f":newer: names {name!r}, which {self.arguments[0]} has already: remove it from :newer:",
                        location=self.get_location())
        have = manifest_field_names(m) | newer
        for name in sorted(have - explained):
            log.warning(f"{self.arguments[0]} has the field {name!r}, which the page's table does not explain",
                        location=self.get_location())
        for name in sorted(explained - have):
            log.warning(f"the page explains {name!r}, which {self.arguments[0]} does not have",
                        location=self.get_location())
        return self.parse_markdown(list(self.content))


def write_figures() -> list[str]:
    """``marks.png``: the die seen from the patterned face, with a close-up of the key sites and the verniers."""
    gds = MASK_SET / _manifest(str(MASK_SET.relative_to(ROOT) / "manifest.json"))["files"]["gds"]
    target = FIGURES / "marks.png"
    if not gds.is_file():
        return [f"fab: {gds} is missing"]
    if target.is_file() and target.stat().st_mtime > gds.stat().st_mtime:
        return []
    import gdstk
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    wanted = {(5, 0), (100, 0)} | {(layer, p) for layer in (10, 11) for p in range(5)}
    lib = gdstk.read_gds(str(gds), filter=wanted)  # the etch layers are not drawn
    cell = lib.top_level()[0]
    colours = {0: "#444444", 1: "#1f77b4", 2: "#ff7f0e", 3: "#2ca02c", 4: "#d62728"}
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.2))
    views = [("whole die", None), ("key sites, lower-left corner", (-6.0, -4.6, -6.0, -4.6)),
             ("plate 1's x vernier, top edge", (-5.35, -4.8, 5.68, 5.9))]
    for ax, (title, box) in zip(axes, views):
        for poly in cell.polygons:
            pts = poly.points * 1e-3  # user unit µm -> mm
            if poly.layer == 5:
                ax.add_patch(Polygon(pts, closed=True, facecolor="#bbbbbb", edgecolor="none"))
            elif poly.layer == 100:
                ax.add_patch(Polygon(pts, closed=True, fill=False, edgecolor="black", linewidth=0.8))
            else:
                window = poly.layer == 10 and poly.area() > 0.05e6  # a clear window, not a cross arm (µm²)
                ax.add_patch(Polygon(pts, closed=True, fill=not window, facecolor=colours[poly.datatype],
                                     edgecolor=colours[poly.datatype], linewidth=0.8, alpha=0.9))
        if box is None:
            ax.set_xlim(-6.3, 6.3)
            ax.set_ylim(-6.3, 6.3)
        else:
            ax.set_xlim(box[0], box[1])
            ax.set_ylim(box[2], box[3])
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm), layout view from the patterned face")
        ax.set_ylabel("y (mm)")
        ax.set_title(title)
    handles = [plt.Line2D([], [], color="#bbbbbb", lw=8, label="chrome (layer 5)")]
    handles += [plt.Line2D([], [], color=c, lw=3, label=f"plate {p} marks (layers 10/{p}, 11/{p})")
                for p, c in colours.items()]
    fig.legend(handles=handles, loc="lower center", ncol=6, frameon=False)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    FIGURES.mkdir(parents=True, exist_ok=True)
    fig.savefig(target, dpi=90)
    plt.close(fig)
    return []


def setup(app) -> None:
    app.add_directive("manifest-table", ManifestTable)
    app.add_directive("manifest-fields", ManifestFields)

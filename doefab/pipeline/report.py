"""``report.md`` and ``report.html`` of a scene run: every stage's pictures and tables, what ran, what was
reused or skipped and why, and an "error against run time" section for every stage that has a knob (each
caption says whether the plot is this run's or a repository-wide benchmark).

The Summary opens with one paragraph in plain words with units (what the part delivers, how many parts meet the
spec, what limits them), then the details as a list. Every figure appears once. Text is written once, in
Markdown's inline form (`code`, **strong**); the HTML renders it (``html_text``)."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

from doefab.applications import design_is
from doefab.io import atomic_write_text, read_json
from doefab.pipeline.knobs import BENCHMARK, REPO, knob_plots
from doefab.pipeline.resolved import ResolvedScene
from doefab.pipeline.stagerun import kept_note

__all__ = ["write_report", "REPORT_FILES", "SECTIONS", "html_text", "deepest_preview", "system_table", "REPO"]

REPORT_FILES = ("report.md", "report.html")  # at the run folder's top, beside run.json
SECTIONS = ("Summary", "Stages", "Design", "Masks", "Holder", "Reconstruction", "Tolerance", "Error against run time")


def html_text(text: str) -> str:
    """Markdown-style inline text as HTML: escaped, with `code` spans rendered as <code>, **strong** ones as
    <strong> and [links](relative/path) as <a>."""
    text = re.sub(r"`([^`]+)`", r"<code>\1</code>", html.escape(text))
    text = re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", r'<a href="\2">\1</a>', text)
    return re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", text)


def write_report(out: Path, scene, done: dict, res: ResolvedScene, quick: bool = False) -> dict:
    """Write report.md and report.html; returns the list of images referenced. ``quick``: the run was
    ``--quick``, which the summary says first (``stages.quick_note``)."""
    from doefab.pipeline.stages import quick_note
    from doefab.pipeline.summary import summary_items

    first = [("p", quick_note(done))] if quick else []
    blocks = [("Summary", first + summary_items(out, done, scene.task)), ("Stages", _stage_items(scene, done, res))]
    blocks += _stage_blocks(out, scene, done)
    blocks.append(("Error against run time", [("p", "Each knob's error against its run time, with the chosen setting "
                                                    "marked; the caption says whether a plot is this run's or a "
                                                    f"{BENCHMARK}.")]
                   + [("img", f, f"{t}: {c}") if f else ("p", f"{t}: {c}")
                      for t, f, c in knob_plots(out, scene, done)]))
    shown: set[str] = set()  # each figure once, where it first appears
    blocks = [(sec, [it for it in items if it[0] != "img" or ((out / it[1]).is_file() and not _seen(shown, it[1]))])
              for sec, items in blocks]
    images = [it[1] for _, items in blocks for it in items if it[0] == "img"]
    md, body = _render(blocks)
    md_file, html_file = REPORT_FILES
    atomic_write_text(out / md_file, "\n".join([f"# doefab report — {scene.path.name}", ""] + md) + "\n")
    atomic_write_text(out / html_file, _page(scene.path.name, body))
    atomic_write_text(out / "report_files" / "images.json", json.dumps(images))
    return {"images": images, "sections": [b[0] for b in blocks]}


def _seen(shown: set, path: str) -> bool:
    if path in shown:
        return True
    shown.add(path)
    return False


def _stage_items(scene, done: dict, res: ResolvedScene) -> list[tuple]:
    """The Stages section: what ran, was reused or skipped and why, and the system it was designed for."""
    stages = [["stage", "status", "why", "seconds"]]
    for name, info in done.items():
        note = kept_note(name, info)
        st = info.get("status", "?") + (f" (unchanged: {note})" if note else "")
        stages.append([name, st, info.get("why", ""), f"{info.get('seconds', 0):.1f}"])
    for name in ("design", "masks", "holder", "reconstruction", "tolerance"):
        if name not in done:
            stages.append([name, "skipped", "not in the scene's stages", "0"])
    s = res.settings
    return [("p", f"Scene `{scene.path}` — task {scene.task}; design {s['design_task']}; "
                  f"{len(s['wavelengths_m'])} wavelength(s), {len(s['depths_m'])} depth plane(s), "
                  f"PSF window {s['kernel_px']} px. Only these samples were computed."),
            ("table", stages), ("p", "The system this run designed for (`doefab doctor` explains the same):"),
            ("table", system_table(res, scene))]


def _stage_blocks(out: Path, scene, done: dict) -> list[tuple[str, list]]:
    """The Design, Masks, Holder, Reconstruction and Tolerance sections."""
    from doefab.pipeline.summary import tolerance_items
    from doefab.reconstruction.metrics import metric_label

    blocks = []
    d = done.get("design")
    if d:
        m = d.get("metric", {})
        blocks.append(("Design", [("p", f"Task metric ({m.get('name', '')}): quantized {m.get('quantized', float('nan')):.4f}, "
                                        f"worst entry {m.get('quantized_worst', float('nan')):.4f}."),
                                  ("img", "design/psf_target_vs_design.png",
                                   "PSFs against their targets, log scale (log10 of the light per pixel, 6 decades "
                                   "below each panel's peak)"),
                                  ("img", "design/height_map.png", "quantized height map")]))
    mk = done.get("masks")
    if mk and mk.get("status") != "skipped":
        blocks.append(("Masks", [("p", f"Mask set: [masks/](masks/). {mk.get('why', '')}"),
                                 ("img", "masks/preview_composite.png", "composite of the etch layers (layout view)"),
                                 ("img", f"masks/{deepest_preview(out / 'masks')}", "the deepest etch layer")]))
    ho = done.get("holder")
    if ho:
        blocks.append(("Holder", [("p", f"DOE {ho.get('doe_to_lens_mm')} mm from the lens glass; files: "
                                        f"{', '.join(ho.get('files', []))}."),
                                  ("img", "holder/render_iso.png", "holder, iso view"),
                                  ("img", "holder/render_side.png", "holder, half section")]))
    rc = done.get("reconstruction")
    if rc and rc.get("status") != "skipped":
        rows = rc.get("rows", {})
        keys = list(next(iter(rows.values())).keys()) if rows else []
        table = [["variant"] + [metric_label(scene.task, k) for k in keys]] + [[v] + [f"{x:.4g}" for x in r.values()]
                                                                               for v, r in rows.items()]
        blocks.append(("Reconstruction", [("p", rc.get("why", "")), ("table", table),
                                          *beside_tolerance(out, scene.task, rows),
                                          ("img", "reconstruction/examples.png", "a held-out test scene")]))
    else:
        blocks.append(("Reconstruction", [("p", (rc or {}).get("why", "not run"))]))
    tl = done.get("tolerance")
    if tl and tl.get("status") == "ran":
        blocks.append(("Tolerance", [("p", tl.get("why", ""))] + tolerance_items(out)))
    else:
        blocks.append(("Tolerance", [("p", (tl or {}).get("why", "not run"))]))
    return blocks


def _json(path: Path) -> dict:
    try:
        got = read_json(path)
    except (OSError, ValueError):
        return {}
    return got if isinstance(got, dict) else {}


def _scenes_text(n, split, size) -> str:
    return f"{n} {split} scene{'' if n == 1 else 's'} of {size}² px"


def beside_tolerance(out: Path, task: str, rows: dict) -> list[tuple]:
    """A paragraph after the reconstruction table: its proposed network's primary metric beside what the tolerance
    study's network judge gives the error-free part and the simulated parts, and why the numbers differ (the
    judge renders on the evaluation's path: the differences left are the parts and the scenes). Nothing without
    a network-level study."""
    from doefab.reconstruction.metrics import DISPLAY, metric_text
    from doefab.tolerance.spec import PRIMARY

    tol, ev = _json(out / "tolerance" / "tolerance.json"), _json(out / "reconstruction" / "metrics.json")
    m = PRIMARY.get(task)
    free = ((tol.get("nominal") or {}).get("network") or {}).get("nominal_psf") or {}
    if m not in free or m not in rows.get("proposed", {}):
        return []
    name, judge, cond = DISPLAY[task][m][0], tol.get("network_judge") or {}, ev.get("conditions") or {}
    table = _scenes_text(ev.get("images", "?"), ev.get("split", "test"), ev.get("size_px", "?"))
    judged = _scenes_text(judge.get("images", "?"), judge.get("split", "?"), judge.get("size", "?"))
    parts = cond.get("parts") or 0
    text = (f"Beside the tolerance study: the table's proposed {name}, {metric_text(task, m, rows['proposed'][m])}, "
            f"is read on {table}" + (f" captured through {parts} fabricated parts" if parts else " (clean captures)")
            + f". The study's network judge makes and scores its captures on the same path (the same split, sensor, "
            f"crosstalk calibration, depth planes and metrics), each part on {judged}: the error-free part "
            f"{metric_text(task, m, free[m])}")
    net = ((tol.get("summary") or {}).get("network") or {}).get("nominal_psf")
    if net and m in net.get("metrics", {}):
        text += f", the mean of its {net['yield']['n']} simulated parts {metric_text(task, m, net['metrics'][m]['mean'])}"
    why = ([f"the table's captures are made through {parts} fabricated parts drawn from the tolerance budget, with "
            f"the sensor's dual-pixel crosstalk, while the error-free part has no fabrication or mounting error and no "
            f"crosstalk"] if parts else [])
    if cond.get("name", "clean") == "clean":
        why.append("the table's captures are clean (the nominal model's own: depth on the network's own planes)")
    if table != judged:
        why.append(f"the scenes differ ({table} against {judged}; crops of a set of another size sit elsewhere on the "
                   f"sensor and see other crosstalk)")
    return [("p", text + (". They differ because " + "; and ".join(why) + "." if why else
                          ". Same scenes, same conditions: the numbers are the same."))]


def _render(blocks) -> tuple[list[str], list[str]]:
    """The sections as Markdown lines and HTML fragments: ("p", text) a paragraph, ("ul", [text]) a list,
    ("img", path, caption) a figure, ("table", rows) a table."""
    md, body = [], []
    for sec, items in blocks:
        md += [f"## {sec}", ""]
        body.append(f'<section id="{sec.lower().replace(" ", "-")}"><h2>{html.escape(sec)}</h2>')
        for it in items:
            if it[0] == "p":
                md += [it[1], ""]
                body.append(f"<p>{html_text(it[1])}</p>")
            elif it[0] == "ul":
                md += [f"- {x}" for x in it[1]] + [""]
                body.append("<ul>" + "".join(f"<li>{html_text(x)}</li>" for x in it[1]) + "</ul>")
            elif it[0] == "img":  # the caption under the figure too: renderers show no alt text
                md += [f"![{it[2].replace('`', '')}]({it[1]})", "", f"*{it[2]}*", ""]
                body.append(f'<figure><img src="{html.escape(it[1])}" alt="{html.escape(it[2].replace("`", ""))}">'
                            f"<figcaption>{html_text(it[2])}</figcaption></figure>")
            else:
                rows = it[1]
                md += ["| " + " | ".join(map(_cell, rows[0])) + " |", "|" + " --- |" * len(rows[0])]
                md += ["| " + " | ".join(map(_cell, r)) + " |" for r in rows[1:]] + [""]
                body.append("<table><thead><tr>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in rows[0])
                            + "</tr></thead><tbody>"  # a header row printing repeats on each page
                            + "".join("<tr>" + "".join(f"<td>{html_text(str(c))}</td>" for c in r) + "</tr>"
                                      for r in rows[1:]) + "</tbody></table>")
        body.append("</section>")
    return md, body


def _cell(value) -> str:
    """A Markdown table cell: a ``|`` of its text escaped (it would split the cell)."""
    return str(value).replace("|", "\\|")


def _page(name: str, body: list[str]) -> str:
    return ("<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>doefab report — {html.escape(name)}</title><style>"
            "body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}"
            "img{max-width:100%;height:auto;border:1px solid #ddd}figure{margin:1em 0}"
            "figcaption{font-size:.85em;color:#555}table{border-collapse:collapse;margin:1em 0;font-size:.9em}"
            "td,th{border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top}"
            "table{display:block;overflow-x:auto}figure,tr{break-inside:avoid}"
            "@media print{table{display:table}}</style></head><body>"
            f"<h1>doefab report — {html.escape(name)}</h1>" + "".join(body) +
            # after loading, the page records which images failed (a browser check reads it from the DOM)
            "<script>window.addEventListener('load',function(){var b=[],im=document.images;"
            "for(var i=0;i<im.length;i++){if(!im[i].complete||!im[i].naturalWidth){b.push(im[i].getAttribute('src'))}}"
            "document.body.setAttribute('data-images',im.length);"
            "document.body.setAttribute('data-broken-images',JSON.stringify(b));});</script>"
            "</body></html>\n")


def system_table(res: ResolvedScene, scene=None) -> list[list[str]]:
    """The resolved scene's camera, bands and fab (and with the ``scene``, its holder's field) as rows (quantity,
    value, what it means)."""
    from doefab.pipeline.doctor import explain

    if getattr(res, "camera", None) is None:  # a report of stages without a resolved scene
        return [["quantity", "value", "what it means"], ["scene", "not resolved", "run doefab doctor on it"]]
    cam = res.camera
    rows = [["quantity", "value", "what it means"],
            ["camera", f"f = {cam.focal_length * 1e3:.4g} mm, DOE aperture {cam.aperture_diameter * 1e3:.4g} mm, "
                       f"sensor pitch {cam.sensor_pitch * 1e6:.4g} µm, DOE pitch {cam.doe_pitch * 1e6:.4g} µm",
             "custom camera" if res.custom_camera else "the preset prototype"],
            ["fabrication", f"{res.settings['n_levels']} levels on {cam.material.name}",
             f"etch depths for {cam.design_wavelength * 1e9:.0f} nm"]]
    if res.sensor is not None:
        spectral = design_is(res.settings.get("design_task"), "spectral")
        own = res.sensor.differs_from(None, spectral)
        rows.append(["sensor", res.sensor.describe(with_response=spectral),
                     "this camera's sensor" if own else "the default (prototype) sensor"])
    for r in explain(res, scene):
        rows.append([r["quantity"], f"{r['value']:.4g} {r['unit']}".strip(), r["meaning"]])
    rows += [["warning", "", note] for note in res.warnings]
    return rows


def deepest_preview(masks: Path) -> str:
    """The file name of a mask set's deepest etch layer preview (``preview_layer<M>.png``)."""
    layers = sorted(masks.glob("preview_layer*.png"), key=lambda p: int(p.stem.removeprefix("preview_layer") or 0))
    return layers[-1].name if layers else "preview_layer4.png"

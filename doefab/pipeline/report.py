"""``report.md`` and ``report.html`` of a scene run: every stage's pictures and tables, what ran, what was
reused or skipped and why, and an "error against run time" section for every stage that has a knob (each
caption says whether the plot is this run's or a repository-wide benchmark).

Text is written once, in Markdown's inline form (`code`); the HTML renders it (``html_text``)."""

from __future__ import annotations

import csv
import html
import json
import re
from pathlib import Path

from doefab.io import atomic_write_text

__all__ = ["write_report", "SECTIONS", "html_text", "deepest_preview", "system_table"]

REPO = Path(__file__).resolve().parents[2]
SECTIONS = ("Summary", "Stages", "Design", "Masks", "Holder", "Reconstruction", "Tolerance", "Error against run time")


BENCHMARK = "repository-wide benchmark, not this run"


def html_text(text: str) -> str:
    """Markdown-style inline text as HTML: escaped, with `code` spans rendered as <code>."""
    return re.sub(r"`([^`]+)`", r"<code>\1</code>", html.escape(text))


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _knob_plots(out: Path, scene, done: dict) -> list[tuple[str, str, str]]:
    """(title, file, caption) of every error-against-run-time plot, each with the chosen setting marked."""
    plt = _plt()
    figs = []
    rdir = out / "report_files"
    rdir.mkdir(exist_ok=True)
    csv_path = REPO / "benchmarks" / "results" / "psf_error_vs_time.csv"
    if csv_path.is_file():
        rows = list(csv.DictReader(open(csv_path)))
        fig, ax = plt.subplots(figsize=(6, 3.8), layout="constrained")
        for r in rows:
            try:
                t, e = float(r["time_s"]), float(r["rel_l2"])
            except (KeyError, ValueError):
                continue
            chosen = r.get("route", "").startswith("spectral (default)")
            ax.scatter(t, e, s=60 if chosen else 20, marker="*" if chosen else "o", color="red" if chosen else "C0")
            if chosen:
                ax.annotate("chosen: spectral, q = 1, float32", (t, e), textcoords="offset points", xytext=(8, 8),
                            fontsize=8, color="red")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("time for a 31-band coded PSF (s, 2-core CPU)")
        ax.set_ylabel("relative L2 error of the PSF")
        ax.set_title(f"PSF sampling and route ({BENCHMARK})", fontsize=9)
        fig.savefig(rdir / "knob_psf.png", dpi=100)
        plt.close(fig)
        figs.append(("PSF sampling", "report_files/knob_psf.png",
                     f"{BENCHMARK}: the 31-band hyperspectral case measured by `benchmarks/psf_error_vs_time.py` "
                     f"(`benchmarks/results/psf_error_vs_time.csv`); the star marks the setting every run uses"))
    hist = out / "design" / "history.csv"
    if hist.is_file():
        rows = list(csv.DictReader(open(hist)))
        fig, ax = plt.subplots(figsize=(6, 3.8), layout="constrained")
        t = [float(r["wall_time_s"]) for r in rows]
        m = [float(r["metric"]) for r in rows]
        ax.plot(t, m)
        ax.plot(t[-1], m[-1], "r*", ms=12, label=f"chosen: {len(rows)} iterations")
        ax.set_xlabel("optimisation wall time (s)")
        ax.set_ylabel("task metric (fraction of coded light in band)")
        ax.legend(fontsize=8)
        fig.savefig(rdir / "knob_design.png", dpi=100)
        plt.close(fig)
        figs.append(("Optimiser iterations", "report_files/knob_design.png", "this run's design history"))
    else:
        table = REPO / "benchmarks" / "results" / "design_metric_vs_time.md"
        rows = []
        if table.is_file():
            from doefab.pipeline.scene import TASK_DESIGN

            want = TASK_DESIGN[scene.task]
            for line in table.read_text().splitlines():
                cells = [c.strip() for c in line.strip("|").split("|")]
                if len(cells) >= 4 and cells[0] == want:
                    try:
                        rows.append((cells[1], float(cells[2]), float(cells[3])))
                    except ValueError:
                        continue
        chosen_run, note = _committed_run(TASK_DESIGN[scene.task]) if rows else (None, "")
        if rows:
            fig, ax = plt.subplots(figsize=(6, 3.8), layout="constrained")
            right = max(r[2] for r in rows)
            for name, metric, secs in rows:
                chosen = chosen_run is not None and name.startswith(chosen_run)
                far = secs > 0.6 * right
                ax.scatter(secs, metric, s=90 if chosen else 25, marker="*" if chosen else "o",
                           color="red" if chosen else "C0")
                ax.annotate(("chosen (committed): " if chosen else "") + name.split(" — ")[0], (secs, metric),
                            textcoords="offset points", xytext=(-6 if far else 6, 4), ha="right" if far else "left",
                            fontsize=7, color="red" if chosen else "black")
            ax.set_xlabel("design wall time (s, 2-core CPU)")
            ax.set_ylabel("quantized task metric (full grid)")
            ax.set_title(f"optimiser and grid against run time ({BENCHMARK})", fontsize=9)
            fig.savefig(rdir / "knob_design.png", dpi=100)
            plt.close(fig)
            figs.append(("Optimiser iterations", "report_files/knob_design.png",
                         f"{BENCHMARK}: this run reused the committed design; the design runs measured by "
                         "`benchmarks/design_metric_vs_time.py` and `benchmarks/nlopt_optimizers.py` (table in "
                         "`benchmarks/results`)" + note))
    from doefab.reconstruction.weights import history_path

    curves = [(v, history_path(scene.task, v)) for v in ("proposed", "coded_only", "uncoded_only")]
    if any(p.is_file() for _, p in curves):
        fig, ax = plt.subplots(figsize=(6, 3.8), layout="constrained")
        metric = None
        for v, p in curves:
            if not p.is_file():
                continue
            rows = [r for r in csv.reader(open(p))]
            metric = rows[0][3]
            pts = [(float(r[1]) / 60, float(r[3])) for r in rows[1:] if r[3] not in ("nan", "")]
            ax.plot([a for a, _ in pts], [b for _, b in pts], label=v.replace("_", "-"))
            if v == "proposed" and pts:
                ax.plot(pts[-1][0], pts[-1][1], "r*", ms=12, label=f"shipped: {pts[-1][0]:.0f} min")
        ax.set_xlabel("training wall time (minutes, 2-core CPU)")
        ax.set_ylabel(f"{metric} on the validation split" + (" (m)" if metric and "mae" in metric else
                                                             " (dB)" if metric and "psnr" in metric else ""))
        ax.legend(fontsize=8)
        fig.savefig(rdir / "knob_training.png", dpi=100)
        plt.close(fig)
        figs.append(("Training time", "report_files/knob_training.png",
                     "the shipped weights' validation curves, recorded when they were trained (`doefab train`), not "
                     "in this run"))
    yv = out / "tolerance" / "yield_vs_n.png"
    if yv.is_file():
        figs.append(("Monte Carlo samples", "tolerance/yield_vs_n.png",
                     "this run's running yield and its 95 % interval; the chosen N is the right end"))
    return figs


def write_report(out: Path, scene, done: dict, res: dict) -> dict:
    """Write report.md and report.html; returns the list of images referenced."""
    from doefab.pipeline.summary import summary_items, tolerance_items

    blocks: list[tuple[str, list]] = []  # (section, [("p", text) | ("img", path, caption) | ("table", rows)])
    blocks.append(("Summary", summary_items(out, done)))
    stages = [["stage", "status", "why", "seconds"]]
    for name, info in done.items():
        st = info.get("status", "?") + (" (unchanged: kept from the previous run)" if info.get("reused_from_previous_run")
                                        else "")
        stages.append([name, st, info.get("why", ""), f"{info.get('seconds', 0):.1f}"])
    for name in ("design", "masks", "holder", "reconstruction", "tolerance"):
        if name not in done:
            stages.append([name, "skipped", "not in the scene's stages", "0"])
    s = res["settings"]
    blocks.append(("Stages", [("p", f"Scene `{scene.path}` — task {scene.task}; design {s['design_task']}; "
                                    f"{len(s['wavelengths_m'])} wavelength(s), {len(s['depths_m'])} depth plane(s), "
                                    f"PSF window {s['kernel_px']} px. Only these samples were computed."),
                              ("table", stages), ("p", "The system this run designed for (`doefab doctor` explains "
                                                       "the same):"), ("table", system_table(res))]))
    d = done.get("design")
    if d:
        m = d.get("metric", {})
        blocks.append(("Design", [("p", f"Task metric ({m.get('name', '')}): quantized {m.get('quantized', float('nan')):.4f}, "
                                        f"worst entry {m.get('quantized_worst', float('nan')):.4f}."),
                                  ("img", "design/psf_target_vs_design.png",
                                   "PSFs against their targets, log scale (log10 of the light per pixel, 6 decades "
                                   "below each panel's peak)"),
                                  ("img", "design/levels.png", "quantized height map")]))
    mk = done.get("masks")
    if mk and mk.get("status") != "skipped":
        blocks.append(("Masks", [("p", f"Mask set: `{mk.get('mask_set')}`. {mk.get('why', '')}"),
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
        units = {"psnr": " (dB)", "psnr_highlight": " (dB)", "sam": " (rad)", "mae": " (m)", "rmse": "", "ssim": "",
                 "rmse_highlight": "", "log10": "", "delta125": ""}
        if scene.task == "depth":
            units["rmse"] = " (m)"
        table = [["variant"] + [k + units.get(k, "") for k in keys]] + [[v] + [f"{x:.4g}" for x in r.values()]
                                                                         for v, r in rows.items()]
        blocks.append(("Reconstruction", [("p", rc.get("why", "")), ("table", table),
                                          ("img", "reconstruction/examples.png", "a held-out test scene")]))
    else:
        blocks.append(("Reconstruction", [("p", (rc or {}).get("why", "not run"))]))
    tl = done.get("tolerance")
    if tl and tl.get("status") == "ran":
        blocks.append(("Tolerance", [("p", tl.get("why", ""))] + tolerance_items(out)))
    else:
        blocks.append(("Tolerance", [("p", (tl or {}).get("why", "not run"))]))
    blocks.append(("Error against run time", [("p", "Each knob's error against its run time, with the chosen setting "
                                                    "marked; the caption says whether a plot is this run's or a "
                                                    f"{BENCHMARK}.")]
                   + [("img", f, f"{t}: {c}") for t, f, c in _knob_plots(out, scene, done)]))
    images = [it[1] for _, items in blocks for it in items if it[0] == "img" and (out / it[1]).is_file()]
    md, body = [f"# doefab report — {scene.path.name}", ""], []
    for sec, items in blocks:
        md += [f"## {sec}", ""]
        body.append(f'<section id="{sec.lower().replace(" ", "-")}"><h2>{html.escape(sec)}</h2>')
        for it in items:
            if it[0] == "p":
                md += [it[1], ""]
                body.append(f"<p>{html_text(it[1])}</p>")
            elif it[0] == "img":
                if not (out / it[1]).is_file():
                    continue
                md += [f"![{it[2]}]({it[1]})", ""]
                body.append(f'<figure><img src="{html.escape(it[1])}" alt="{html.escape(it[2].replace("`", ""))}">'
                            f"<figcaption>{html_text(it[2])}</figcaption></figure>")
            else:
                rows = it[1]
                md += ["| " + " | ".join(rows[0]) + " |", "|" + " --- |" * len(rows[0])]
                md += ["| " + " | ".join(map(str, r)) + " |" for r in rows[1:]] + [""]
                body.append("<table><tr>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in rows[0]) + "</tr>"
                            + "".join("<tr>" + "".join(f"<td>{html_text(str(c))}</td>" for c in r) + "</tr>"
                                      for r in rows[1:]) + "</table>")
        body.append("</section>")
    page = ("<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>doefab report</title><style>"
            "body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}"
            "img{max-width:100%;height:auto;border:1px solid #ddd}figure{margin:1em 0}"
            "figcaption{font-size:.85em;color:#555}table{border-collapse:collapse;margin:1em 0;font-size:.9em}"
            "td,th{border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top}</style></head><body>"
            f"<h1>doefab report — {html.escape(scene.path.name)}</h1>" + "".join(body) +
            # after loading, the page records which images failed (a browser check reads it from the DOM)
            "<script>window.addEventListener('load',function(){var b=[],im=document.images;"
            "for(var i=0;i<im.length;i++){if(!im[i].complete||!im[i].naturalWidth){b.push(im[i].getAttribute('src'))}}"
            "document.body.setAttribute('data-images',im.length);"
            "document.body.setAttribute('data-broken-images',JSON.stringify(b));});</script>"
            "</body></html>\n")
    atomic_write_text(out / "report.md", "\n".join(md) + "\n")
    atomic_write_text(out / "report.html", page)
    atomic_write_text(out / "report_files" / "images.json", json.dumps(images))
    return {"images": images, "sections": [b[0] for b in blocks]}


def system_table(res: dict) -> list[list[str]]:
    """The resolved scene's camera, bands and fab as rows (quantity, value, what it means)."""
    from doefab.pipeline.doctor import explain

    if "camera" not in res:  # a report of stages without a resolved scene
        return [["quantity", "value", "what it means"], ["scene", "not resolved", "run doefab doctor on it"]]
    cam = res["camera"]
    rows = [["quantity", "value", "what it means"],
            ["camera", f"f = {cam.focal_length * 1e3:.4g} mm, DOE aperture {cam.aperture_diameter * 1e3:.4g} mm, "
                       f"sensor pitch {cam.sensor_pitch * 1e6:.4g} µm, DOE pitch {cam.doe_pitch * 1e6:.4g} µm",
             "custom camera" if res.get("custom_camera") else "the preset prototype"],
            ["fabrication", f"{res['settings']['levels']} levels on {cam.material.name}",
             f"etch depths for {cam.design_wavelength * 1e9:.0f} nm"]]
    if res.get("sensor") is not None:
        spectral = res["settings"].get("design_task") == "grating"
        own = res["sensor"].differs_from(None, spectral)
        rows.append(["sensor", res["sensor"].describe(with_response=spectral),
                     "this camera's sensor" if own else "the default (prototype) sensor"])
    for r in explain(res):
        rows.append([r["quantity"], f"{r['value']:.4g} {r['unit']}".strip(), r["meaning"]])
    rows += [["warning", "", note] for note in res.get("warnings", [])]
    return rows


def deepest_preview(masks: Path) -> str:
    """The file name of a mask set's deepest etch layer preview (``preview_layer<M>.png``)."""
    layers = sorted(masks.glob("preview_layer*.png"), key=lambda p: int(p.stem.removeprefix("preview_layer") or 0))
    return layers[-1].name if layers else "preview_layer4.png"


def _committed_run(design_name: str) -> tuple[str | None, str]:
    """Which row of the pixel-wise optimiser/grid benchmark the committed design is (None when it is not one of
    them, e.g. the radial half-ring, whose metric follows another ring law), and a caption note saying so."""
    from doefab.design.committed import committed_dir
    from doefab.design.design import Design

    try:
        cfg = Design.load(committed_dir(design_name)).extra.get("config", {})
    except Exception:  # noqa: BLE001 - the figure is a courtesy; a missing design only drops the star
        return None, ""
    if cfg.get("parameterization", "pixel") != "pixel":
        law = cfg.get("task_params", {}).get("ring_law")
        return None, (f"; the committed design is {cfg.get('parameterization')}"
                      + (f" with the {law} ring law" if law else "")
                      + ", not one of these pixel-wise runs (its metric is not on this scale): README, Depth DOE")
    if cfg.get("optimizer", "adam") != "adam":
        return None, ""
    return ("adam, full grid" if int(cfg.get("sampling", 1)) == 1 else "adam, half grid"), ""

"""``diagnosis.json`` and ``diagnosis.html``: a fitted part's errors against its budget, in numbers and in words.

``diagnosis.json`` (``assemble``) holds, units in the keys: ``errors`` per mask (mask 1 = the shallowest etch, as
in the mask set's manifest; overlays relative to the plate each aligns to, x right and y up in the design's frame,
seen from the scene) and per part, each with its σ and whether the recordings identify it (``reason`` where not);
``against_budget``: every error's deviation from nominal over the budget's σ (z); the ``misfit`` of the
error-free and the fitted part; the task's PSF metric error-free, as measured and as fitted; what the fitted part
``delivered`` through the task's network (when asked: it renders scenes); how the fit ran.

``diagnosis.html`` (``write_report``) says first what the part delivers, which identified errors lie outside the
budget (|z| > ``OUTSIDE``) and what to do — re-make a mask, re-make the lithography, re-mount the die, fine-tune
the networks, or nothing — then the tables and the measured PSFs beside the fitted ones.
"""

from __future__ import annotations

import html
import math

import numpy as np

from doefab.errors import DoefabError
from doefab.io import atomic_write_text
from doefab.lab.partmodel import BOUND, FINE
from doefab.validate import distance_record

__all__ = ["assemble", "check_design", "delivered_metric", "actions", "write_report", "deviations", "OUTSIDE",
           "FINETUNE_LOSS",
           "DELIVERED_SCENES", "DELIVERED_SIZE", "FORMAT", "VERSION"]

FORMAT, VERSION = "doefab-diagnosis", 1
OUTSIDE = 2.0  # |z| beyond which an identified error is outside the budget
FINETUNE_LOSS = 0.01  # a PSF metric this far below the error-free part's: fine-tune the networks for the part
DELIVERED_SCENES, DELIVERED_SIZE = 4, 128  # the network judge's scenes for ``delivered`` (few and small: minutes)


def check_design(measured, design) -> None:
    """Refuse a pair whose provenance names another design's level map (``levels_sha256``) than ``design``'s."""
    from doefab.fabrication.levels import levels_sha256

    prov = getattr(measured, "provenance", None) or {}
    theirs, mine = prov.get("levels_sha256"), levels_sha256(design.levels)
    if theirs and theirs != mine:
        where = f" (calibrated with {prov['design']})" if prov.get("design") else ""
        raise DoefabError(f"the measured pair belongs to the design with levels_sha256 {theirs[:16]}…{where}, not to "
                          f"this one ({mine[:16]}…): give --design the design folder (or mask set) the part was made "
                          f"from, the one whose design.json lists levels_sha256 {theirs[:16]}…")


def _value(p, x_i) -> float:
    """The error's value in its unit (SI nominal + x budget σ)."""
    return (p.nominal + (0.0 if p.reason else x_i * p.sigma)) / p.si


def _rows(model, x, cur) -> list[dict]:
    """One row per error of the model: its Param, value and σ in its unit, identifiable, reason, z."""
    out, free = [], iter(range(len(model.free)))
    for p in model.params:
        i = None if p.reason else next(free)
        sig = None if i is None or not math.isfinite(cur["sigma"][i]) else float(cur["sigma"][i] * p.sigma / p.si)
        v = _value(p, 0.0 if i is None else x[i])
        out.append({"p": p, "value": v, "sigma": sig, "identifiable": bool(i is not None and cur["identifiable"][i]),
                    "reason": p.reason or (cur["reason"][i] if i is not None else ""),
                    "z": 0.0 if i is None else float(x[i]), "at_bound": i is not None and abs(x[i]) >= 0.999 * BOUND})
    return out


def _errors(rows: list[dict], n_masks: int) -> dict:
    """The ``errors`` record of the contract (units in the keys)."""
    def one(r):
        d = {"value": r["value"], "sigma": r["sigma"], "identifiable": r["identifiable"]}
        return {**d, "reason": r["reason"]} if r["reason"] else d

    def two(rx, ry):
        d = {"x": rx["value"], "y": ry["value"], "sigma_x": rx["sigma"], "sigma_y": ry["sigma"],
             "identifiable": rx["identifiable"] and ry["identifiable"], "identifiable_x": rx["identifiable"],
             "identifiable_y": ry["identifiable"]}
        why = "; ".join(f"{a}: {r['reason']}" for a, r in (("x", rx), ("y", ry)) if r["reason"])
        return {**d, "reason": why} if why else d
    by = {(r["p"].key, r["p"].mask, r["p"].axis): r for r in rows}
    return {"etch_depth_scale": [one(by["etch_depth_scale", m, None]) for m in range(n_masks)],
            "overlay_um": [two(by["overlay", m, "x"], by["overlay", m, "y"]) for m in range(n_masks)],
            "edge_bias_um": one(by["edge_bias", None, None]),
            "mount_decenter_mm": two(by["mount_decenter", None, "x"], by["mount_decenter", None, "y"]),
            "mount_rotation_deg": one(by["mount_rotation", None, None]),
            "axial_gap_mm": one(by["axial_gap", None, None])}


def _against(rows: list[dict]) -> list[dict]:
    """Every error's deviation from nominal (etch depth in %, the gap from the holder's nominal gap), its σ (None:
    not computed) and the budget's σ in the error's unit, and z = deviation / budget σ."""
    out = []
    for r in rows:
        p = r["p"]
        unit, per = p.shown
        dev = (r["value"] - p.nominal / p.si) * per
        name = p.label + (" (from the holder's nominal gap)" if p.key == "axial_gap" else "")
        group = "mask" if p.mask is not None else "lithography" if p.key == "edge_bias" else "mount"
        out.append({"error": name, "value": dev, "budget_sigma": p.sigma / p.si * per, "unit": unit,
                    "sigma": None if r["sigma"] is None else r["sigma"] * per,
                    "z": r["z"], "identifiable": r["identifiable"], "group": group,
                    "mask": None if p.mask is None else p.mask + 1, **({"reason": r["reason"]} if r["reason"] else {})})
    return out


def deviations(err, n_masks: int) -> dict:
    """{``against_budget`` error name: the deviation from nominal of the part ``err`` (a ``PartErrors``, SI) in
    that row's unit}: a known part's errors as a diagnosis states them, to set the two side by side."""
    t = err.for_masks(n_masks)
    out = {f"etch depth mask {m + 1}": (t.depth_scale[m] - 1) * 100 for m in range(n_masks)}
    for m in range(n_masks):
        out[f"overlay mask {m + 1} x"], out[f"overlay mask {m + 1} y"] = (v * 1e6 for v in t.overlay[m])
    out.update({"edge bias": t.edge_bias * 1e6, "decenter x": t.mount_shift[0] * 1e3,
                "decenter y": t.mount_shift[1] * 1e3, "mount rotation": math.degrees(t.mount_rotation)})
    return out


def assemble(model, got: dict, cur: dict, misfit: dict, psf_metric: dict, delivered: dict, run: dict) -> dict:
    """The ``diagnosis.json`` record of a fit (``diagnose.fit``'s ``got``, ``uncertainty.estimate``'s ``cur``)."""
    from doefab.fabrication.levels import levels_sha256

    rows = _rows(model, got["x"], cur)
    against = _against(rows)
    d = model.design
    out = {"format": FORMAT, "version": VERSION, "design_levels_sha256": levels_sha256(d.levels), "misfit": misfit,
           "errors": _errors(rows, model.n_masks), "against_budget": against,
           "psf_metric": {"metric": d.metrics.get("name", "task metric"), **psf_metric}, "delivered": delivered,
           "uncertainty": {"method": "curvature", "s2": cur["s2"],
                           "noise_model": "per half, plane and band: pixel variance a·PSF + b, fitted to the residuals",
                           "noise": got["noise"],
                           **({"held_errors": cur["held"]} if "held" in cur else {})},
           "fit": {"optimizer": "levenberg-marquardt (scipy.optimize.least_squares, trf)", "bound_budget_sigma": BOUND,
                   "grid": f"the design grid (1×), then Gauss–Newton steps on a {FINE}× grid",
                   "parts": run["parts"], "seconds": run["seconds"],
                   "starts": run["starts"], "at_bound": [r["p"].label for r in rows if r["at_bound"]]},
           "measured": {"halves": list(model.halves), "wavelengths_nm": [d.wavelengths[i] * 1e9 for i in model.wl],
                        "depths_m": [distance_record(d.depths[i]) for i in model.dz]},
           "model": {"corner_rounding_um": model.base.corner_rounding * 1e6,
                     "not_fitted": ["mask rotation", "surface roughness", "dual-pixel crosstalk"]}}
    out["actions"] = actions(out)
    return out


def delivered_metric(model, err, compute: bool) -> dict:
    """The task's primary delivered metric through its shipped network (``tolerance.netjudge.NetworkJudge``,
    ``DELIVERED_SCENES`` scenes of ``DELIVERED_SIZE``² px) for the error-free and the fitted part, the network told
    the part's own pair; or why it was not computed."""
    from doefab.applications import of_design
    from doefab.tolerance.errors import PartErrors
    from doefab.tolerance.spec import PRIMARY

    task = getattr(of_design(model.design.task), "name", None)
    out = {"metric": PRIMARY.get(task, "none"), "nominal": None, "as_fitted": None, "computed": False}
    if not compute:
        return {**out, "reason": "not computed: it renders scenes through the part's network (minutes on a CPU); "
                                 "pass --delivered (API: delivered=True)"}
    if task is None or model.design_dir is None:
        return {**out, "reason": f"no network judges a {model.design.task} design given in memory"}
    from doefab.tolerance.judge import PSFJudge
    from doefab.tolerance.netjudge import NetworkJudge

    try:
        judge = NetworkJudge(PSFJudge(model.design_dir, 1, device=model.judge.device), images=DELIVERED_SCENES,
                             size=DELIVERED_SIZE)
    except DoefabError as exc:
        return {**out, "reason": f"not computed: {exc}"}
    m = out["metric"]
    return {**out, "nominal": judge.evaluate(PartErrors())["measured_psf"][m],
            "as_fitted": judge.evaluate(err)["measured_psf"][m], "computed": True,
            "scenes": DELIVERED_SCENES, "size_px": DELIVERED_SIZE, "split": judge.split}


def _dev(r: dict) -> str:
    return f"{r['error']} {r['value']:+.3g} {r['unit']} ({r['z']:+.1f} σ)".replace("  ", " ")


def actions(diag: dict) -> list[str]:
    """What to do about the part, in words, from a ``diagnosis.json`` record: re-make each mask with an identified
    error outside the budget (|z| > ``OUTSIDE``), the lithography for an edge bias outside it, re-mount the die for
    a mount error outside it; fine-tune the networks for the part when its measured PSF metric falls more than
    ``FINETUNE_LOSS`` below the error-free part's; diagnose again with a wider budget when the fit holds errors at
    its bound; else nothing."""
    out_rows = [r for r in diag["against_budget"] if r["identifiable"] and abs(r["z"]) > OUTSIDE]
    todo = []
    for k in sorted({r["mask"] for r in out_rows if r["group"] == "mask"}):
        rows = [r for r in out_rows if r["mask"] == k]
        fixes = [f for f, key in (("realign it", "overlay"), ("etch it to its nominal depth", "etch"))
                 if any(r["error"].startswith(key) for r in rows)]
        todo.append(f"re-make mask {k}'s step (plate {k}: {' and '.join(fixes)}): {'; '.join(map(_dev, rows))}")
    litho = [r for r in out_rows if r["group"] == "lithography"]
    if litho:
        todo.append(f"re-make the lithography (exposure dose, etch undercut): {_dev(litho[0])}")
    mount = [r for r in out_rows if r["group"] == "mount"]
    if mount:
        todo.append("re-mount the die in its holder: " + "; ".join(_dev(r) for r in mount))
    pm = diag["psf_metric"]
    loss = pm["nominal"] - pm["as_measured"]
    if loss > FINETUNE_LOSS:
        todo.append(f"fine-tune the networks for this part (doefab finetune --psf psf_pair_fitted.npz): its PSF metric "
                    f"is {pm['as_measured']:.3f} as measured against {pm['nominal']:.3f} for the error-free part")
    held = diag.get("fit", {}).get("at_bound", [])
    if held:  # the fit ran into its bound: the part lies beyond what the budget describes, or the recordings are off
        todo.insert(0, f"diagnose again with a wider budget (--budget): the fit holds {', '.join(held)} at its bound "
                       f"(±{BOUND:g} budget σ), so this part is further off than the budget describes, or its "
                       f"recordings are not this design's as the recordings file says (check which view is coded, "
                       f"the frames' orientation and the wavelengths); until then the other words here are no "
                       f"diagnosis")
    if not todo:
        todo.append(f"nothing: every identified error is within the budget (|z| ≤ {OUTSIDE:g}) and the PSF metric "
                    f"within {FINETUNE_LOSS:g} of the error-free part's; give the networks the part's pair "
                    f"(--psf psf_pair_fitted.npz)")
    return todo


def _entries(measured, fitted) -> list[tuple[int, int, int, int]]:
    """(measured plane, band, fitted plane, band) of every measured entry, in the fitted pair's lists."""
    def at(have, v):
        return next(i for i, h in enumerate(have) if h == v or (math.isfinite(h) and math.isclose(h, v, rel_tol=1e-6)))
    return [(zi, wi, at(fitted.depths, z), at(fitted.wavelengths, w))
            for zi, z in enumerate(measured.depths) for wi, w in enumerate(measured.wavelengths)]


def _images(measured, fitted, entry, half: str) -> tuple[np.ndarray, np.ndarray]:
    """(measured, fitted scaled to the measured light) PSFs of one entry and half."""
    zi, wi, fz, fw = entry
    m = np.asarray(getattr(measured, half)[zi, wi], np.float64)
    f = np.asarray(getattr(fitted, half)[fz, fw], np.float64)
    return m, f * (m.sum() / max(float(f.sum()), 1e-300))


MAX_ROWS = 6  # figure rows (half × entry) drawn; the table lists all


def _figure(measured, fitted) -> str:
    """Measured, fitted and their difference per half and measured entry, as an embedded PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    from doefab.lab.calreport import figure_html

    rows = [(e, h) for e in _entries(measured, fitted) for h in ("coded", "uncoded")][:MAX_ROWS]
    fig, axes = plt.subplots(len(rows), 3, figsize=(9, 2.8 * len(rows)), squeeze=False)
    for (e, h), ax in zip(rows, axes):
        m, f = _images(measured, fitted, e, h)
        top = float(max(m.max(), f.max(), 1e-30))
        lim = float(max(np.abs(m - f).max(), 1e-30))
        what = f"{'coded' if h == 'coded' else 'plain'} half, {measured.wavelengths[e[1]] * 1e9:.4g} nm, " \
               f"{'∞' if math.isinf(measured.depths[e[0]]) else f'{measured.depths[e[0]]:g} m'}"
        for a, img, title in ((ax[0], m, "measured"), (ax[1], f, "fitted")):
            a.imshow(np.maximum(img, top * 1e-4), norm=LogNorm(top * 1e-4, top), cmap="inferno", origin="upper")
            a.set_title(f"{title}, {what}\nlog scale {top * 1e-4:.1e} … {top:.1e}", fontsize=7)
        ax[2].imshow(m - f, cmap="RdBu_r", vmin=-lim, vmax=lim, origin="upper")
        ax[2].set_title(f"measured − fitted\nblue −{lim:.1e} … red +{lim:.1e}", fontsize=7)
        for a in ax:
            a.set_xticks([])
            a.set_yticks([])
    fig.tight_layout()
    return figure_html(fig, "measured and fitted PSFs")


def _table(head: list[str], rows: list[list]) -> str:
    cells = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return "<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + f"</tr>{cells}</table>"


def _summary(diag: dict) -> list[str]:
    """The words that open the page: what the part delivers, what lies outside the budget, what to do."""
    pm, dl = diag["psf_metric"], diag["delivered"]
    parts = [f"<p><b>What the part delivers.</b> Its PSF metric ({html.escape(str(pm['metric']))}) is "
             f"{pm['as_measured']:.3f} as measured and {pm['as_fitted']:.3f} as fitted, against {pm['nominal']:.3f} "
             f"for the error-free part, over the recorded bands and planes."]
    if dl.get("computed"):
        parts.append(f" Through the task's network ({dl['scenes']} scenes of {dl['size_px']}² px, the network told the "
                     f"part's pair) it delivers {dl['metric']} {dl['as_fitted']:.4g}, against {dl['nominal']:.4g} for "
                     f"the error-free part.")
    else:
        parts.append(f" Delivered quality: {html.escape(dl.get('reason', 'not computed'))}.")
    out = ["".join(parts) + "</p>"]
    outside = [r for r in diag["against_budget"] if r["identifiable"] and abs(r["z"]) > OUTSIDE]
    listed = ", ".join(html.escape(_dev(r)) for r in outside) if outside else "none"
    out.append(f"<p><b>Outside the budget</b> (identified errors beyond ±{OUTSIDE:g} σ): {listed}.</p>")
    out.append("<p><b>What to do.</b></p><ul>" + "".join(f"<li>{html.escape(a)}</li>" for a in diag["actions"])
               + "</ul>")
    hidden = [r for r in diag["against_budget"] if not r["identifiable"]]
    if hidden:
        out.append("<p><b>Not identified</b> (their values are one of many that fit alike):</p><ul>"
                   + "".join(f"<li>{html.escape(r['error'])}: {html.escape(r['reason'])}</li>" for r in hidden)
                   + "</ul>")
    if diag["fit"]["at_bound"]:
        out.append(f"<p>At the fit's bound (±{BOUND:g} budget σ), so larger than the budget allows for: "
                   + html.escape(", ".join(diag["fit"]["at_bound"])) + "; give a wider budget to see how large.</p>")
    return out


def write_report(path, diag: dict, measured, fitted) -> str:
    """Write ``diagnosis.html`` atomically: ``diag`` the diagnosis record, ``measured`` the pair it fitted and
    ``fitted`` the fitted part's pair (``diagnose.fitted_pair``). Returns the path."""
    from doefab.lab.calreport import _STYLE

    rows = [[r["error"], f"{r['value']:+.4g}", "—" if r["sigma"] is None else f"{r['sigma']:.2g}", r["unit"],
             f"{r['budget_sigma']:.3g}", f"{r['z']:+.2f}", "yes" if r["identifiable"] else "no"]
            for r in diag["against_budget"]]
    resid = []
    for e in _entries(measured, fitted):
        for h in ("coded", "uncoded"):
            m, f = _images(measured, fitted, e, h)
            resid.append([h, f"{measured.wavelengths[e[1]] * 1e9:.4g}", str(measured.depths[e[0]]),
                          f"{float(np.abs(m - f).sum() / max(m.sum(), 1e-300)):.3f}"])
    fit = diag["fit"]
    parts = ["<h1>Diagnosis of a fabricated part</h1>", *_summary(diag), "<h2>Each error against the budget</h2>",
             _table(["error", "deviation from nominal", "σ", "unit", "budget σ", "z (budget σ)", "identified"],
                    rows),
             "<p>Overlays are relative to the plate each mask aligns to (the manifest's alignment chain), x right and "
             "y up in the design's frame seen from the scene; mask 1 is the shallowest etch. Uncertainties: "
             f"{html.escape(diag['uncertainty']['method'])} (see diagnosis.json).</p>",
             "<h2>Misfit and PSF metric</h2>",
             _table(["part", "misfit (Σ squared PSF difference)", "PSF metric"],
                    [["error-free", f"{diag['misfit']['nominal']:.4g}", f"{diag['psf_metric']['nominal']:.4f}"],
                     ["fitted", f"{diag['misfit']['fitted']:.4g}", f"{diag['psf_metric']['as_fitted']:.4f}"],
                     ["measured", "—", f"{diag['psf_metric']['as_measured']:.4f}"]]),
             "<h2>Measured and fitted PSFs</h2>", _figure(measured, fitted),
             _table(["half", "band (nm)", "depth (m)", "Σ|measured − fitted| / Σ measured"], resid),
             "<h2>How the fit ran</h2>",
             f"<p>{html.escape(fit['optimizer'])} on {html.escape(fit['grid'])}, {len(fit['starts'])} start(s), "
             f"{fit['parts']} parts computed in {fit['seconds']:.0f} s; misfit per start: "
             + ", ".join(f"{s['misfit']:.4g}" for s in fit["starts"]) + ".</p>"]
    page = (f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>doefab diagnosis</title>"
            f"<style>{_STYLE}</style></head><body>{''.join(parts)}</body></html>\n")
    return atomic_write_text(path, page)

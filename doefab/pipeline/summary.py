"""The report's opening: what the part will deliver and how sure that is, its yield against the spec, what limits
it and what would buy the most, and the files to send to the fab and to the printer."""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["summary_items", "tolerance_items"]


def _tolerance(out: Path) -> dict | None:
    p = out / "tolerance" / "tolerance.json"
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


def _files(out: Path, done: dict) -> list[str]:
    """Deliverables: the mask set (layout, manifest, README for the fab) and the holder's printable files."""
    items = []
    mk = done.get("masks") or {}
    if mk.get("mask_set"):
        folder = Path(mk["mask_set"])
        layouts = sorted(p.name for p in folder.glob("*.gds")) + sorted(p.name for p in folder.glob("*.oas"))
        items.append(f"to the fab: {folder}/ ({', '.join(layouts + ['manifest.json', 'README.txt'])})")
    ho = done.get("holder") or {}
    if ho.get("files"):
        items.append(f"to the printer: {out / 'holder'}/ ({', '.join(ho['files'])})")
    return items


def summary_items(out: Path, done: dict) -> list[tuple]:
    """The Summary section's items (("p", text), ...)."""
    from doefab.tolerance.report import summary_lines

    items = []
    tol = _tolerance(out)
    if tol is not None:
        items += [("p", line.replace("**", "")) for line in summary_lines(tol)]
    else:
        items.append(("p", "No tolerance study in this scene: add a [tolerance] section for what the part delivers "
                           "and its yield."))
    items += [("p", f) for f in _files(out, done)]
    return items


def tolerance_items(out: Path) -> list[tuple]:
    """The Tolerance section's tables and figures from tolerance/tolerance.json."""
    tol = _tolerance(out)
    if tol is None:
        return []
    items = []
    g = tol.get("grid", {})
    if g.get("kinds"):
        rows = [["error", "budget 1σ", "bound on the PSF metric at 1×", "grid used"]]
        rows += [[k, f"{v['value']:.3g} {v['unit']}", f"{v['bound'].get('1', v['bound'].get(1, float('nan'))):.2g}",
                  f"{v['grid']}×"] for k, v in g["kinds"].items()]
        items += [("p", f"Grid each error was judged on (measured on a {g['block_px']}² block of the design; the "
                        f"Monte Carlo ran on {g['monte_carlo_grid']}×):"), ("table", rows)]
    rows = [["error (alone, at the budget's 1σ)", "PSF metric change",
             "delivered change, network told the nominal PSF", "told the part's measured PSF"]]
    for r in tol.get("tornado", []):
        d = r.get("network_delta", {})
        cells = [", ".join(f"{k} {v:+.3g}" for k, v in d[lab].items()) if lab in d else "not judged through the network"
                 for lab in ("nominal_psf", "measured_psf")]
        rows.append([f"{r['error']} ({r['value']:.3g} {r['unit']})", f"{r['delta']:+.4f}", *cells])
    items.append(("table", rows))
    for f, cap in (("tolerance/delivered.png", "what the parts deliver through the network (histogram over parts)"),
                   ("tolerance/tornado.png", "each error alone at one standard deviation of the budget (PSF metric)"),
                   ("tolerance/yield_vs_n.png", "yield against the number of parts (95 % Wilson interval)"),
                   ("tolerance/quantization.png", "quantization study")):
        if (out / f).is_file():
            items.append(("img", f, cap))
    return items

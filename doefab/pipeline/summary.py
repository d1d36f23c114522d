"""The report's opening: one paragraph in plain words with units (what the part will deliver and how sure that is,
its yield against the spec, what limits it most), then the details (what would buy the most, warnings, the
aperture stop) and the files to send to the fab and to the printer."""

from __future__ import annotations

from pathlib import Path

from doefab.io import read_json

__all__ = ["summary_items", "tolerance_items"]


def _tolerance(out: Path) -> dict | None:
    p = out / "tolerance" / "tolerance.json"
    try:
        return read_json(p)
    except (OSError, ValueError):
        return None


def _files(out: Path, done: dict) -> list[str]:
    """Deliverables: the mask set (layout, manifest, README for the fab) and the holder's printable files."""
    items = []
    mk = done.get("masks") or {}
    if mk.get("mask_set"):
        folder = out / "masks"  # the run's own copy (the recorded path is where the run was: folders move)
        layouts = sorted(p.name for p in folder.glob("*.gds")) + sorted(p.name for p in folder.glob("*.oas"))
        items.append(f"to the fab: {_links('masks', layouts + ['manifest.json', 'README.txt'])}")
    ho = done.get("holder") or {}
    if ho.get("files"):
        items.append(f"to the printer: {_links('holder', ho['files'])}")
    return items


def _links(folder: str, names: list[str]) -> str:
    """A folder of the run and its files as links relative to the report (which sits at the run folder's top, so
    they hold wherever the folder is copied)."""
    from urllib.parse import quote

    # the targets percent-encoded: a name with a space or parenthesis would end a Markdown link's target
    return f"[{folder}/]({quote(folder)}/) (" + ", ".join(f"[{n}]({quote(f'{folder}/{n}')})" for n in names) + ")"


def summary_items(out: Path, done: dict, task: str) -> list[tuple]:
    """The Summary section's items: one paragraph in plain words with units, then the details and the files as a
    list (("p", text), ("ul", [text, ...]))."""
    from doefab.tolerance.reporttext import lead_text, summary_lines

    tol = _tolerance(out)
    lead = lead_text(tol) if tol is not None else None
    details = [line.removeprefix("- ") for line in summary_lines(tol)] if tol is not None else []
    listed = details + _files(out, done)
    return [("p", lead or _untoleranced_lead(done, task, tol is not None))] + ([("ul", listed)] if listed else [])


def _untoleranced_lead(done: dict, task: str, studied: bool) -> str:
    """The opening without a Monte Carlo: what the error-free part delivers through the network, if it ran."""
    from doefab.reconstruction.metrics import DISPLAY, metric_text
    from doefab.tolerance.spec import PRIMARY

    none = ("the tolerance study ran no Monte Carlo, so nothing is said about the yield" if studied else
            "no tolerance study ran, so nothing is said about fabricated parts or their yield: add a [tolerance] "
            "section to the scene for what they deliver")
    proposed = ((done.get("reconstruction") or {}).get("rows") or {}).get("proposed", {})
    m = PRIMARY.get(task)
    if m not in proposed:
        return none[0].upper() + none[1:] + "."
    return (f"The error-free part delivers {metric_text(task, m, proposed[m])} {DISPLAY[task][m][0]} through the "
            f"task's network on held-out test scenes; {none}.")


def tolerance_items(out: Path) -> list[tuple]:
    """The Tolerance section's tables and figures from tolerance/tolerance.json."""
    from doefab.tolerance.reporttext import NOISE_NOTE, delta_text, signed_change

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
        ci = r.get("network_delta_ci95", {})
        cells = [delta_text(tol["task"], d[lab], ci.get(lab)) if lab in d else "not judged through the network"
                 for lab in ("nominal_psf", "measured_psf")]
        rows.append([f"{r['error']} ({r['value']:.3g} {r['unit']})", signed_change(r['delta']), *cells])
    items.append(("table", rows))
    if any("network_delta_ci95" in r for r in tol.get("tornado", [])):
        items.append(("p", NOISE_NOTE))
    for f, cap in (("tolerance/delivered.png", "what the parts deliver through the network (histogram over parts)"),
                   ("tolerance/tornado.png", "each error alone at one standard deviation of the budget (PSF metric)"),
                   ("tolerance/quantization.png", "quantization study")):  # the yield against N: a knob's figure
        if (out / f).is_file():
            items.append(("img", f, cap))
    return items

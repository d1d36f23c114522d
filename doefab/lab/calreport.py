"""``calibration.html``: what ``doefab calibrate`` measured, in one self-contained page (figures embedded as PNG).

Sections: a summary; the recordings (frames, shift, signal, photons, signal-to-noise); per plane the measured PSFs
beside the nominal ones and their residual maps; the encircled-energy curves; the crosstalk profile with its
standard errors; the provenance.
"""

from __future__ import annotations

import base64
import html
import io
import math

import numpy as np

from doefab.io import atomic_write_text

__all__ = ["write_report", "figure_html", "encircled_energy"]

MAX_BANDS = 6  # bands drawn per plane (evenly chosen when there are more; the tables list all)
_HALVES = (("coded", "coded (DOE) half"), ("uncoded", "plain half"))


def figure_html(fig, alt: str) -> str:
    """An ``<img>`` holding ``fig`` as an embedded PNG (the figure is closed)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def encircled_energy(psf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(radii in pixels, fraction of the kernel's light within each radius of the chief ray, pixel (K//2, K//2))."""
    k = psf.shape[-1]
    yy, xx = np.mgrid[:k, :k] - k // 2
    r = np.hypot(yy, xx).ravel()
    order = np.argsort(r, kind="stable")
    cum = np.cumsum(psf.ravel()[order])
    radii = np.arange(0, k // 2 + 1, dtype=np.float64)
    idx = np.searchsorted(r[order], radii, side="right") - 1
    total = float(psf.sum())
    return radii, cum[idx] / total if total > 0 else np.zeros_like(radii)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _shown_bands(n: int) -> list[int]:
    return list(range(n)) if n <= MAX_BANDS else sorted({int(round(i)) for i in np.linspace(0, n - 1, MAX_BANDS)})


def _depth(z: float) -> str:
    return "∞" if math.isinf(z) else f"{z:g} m"


def _plane_figure(pair, nominal: dict, zi: int) -> str:
    """Measured, nominal and residual maps of both halves at plane ``zi`` (rows: bands); each panel's scale is in
    its title (a colour bar per panel would cost seconds per figure)."""
    from matplotlib.colors import LogNorm

    plt = _plt()
    bands = _shown_bands(len(pair.wavelengths))
    k = pair.coded.shape[-1]
    half_um = k / 2 * pair.sensor_pitch * 1e6
    ext = (-half_um, half_um, -half_um, half_um)
    fig, axes = plt.subplots(len(bands), 6, figsize=(15, 2.6 * len(bands) + 0.5), squeeze=False)
    for row, b in enumerate(bands):
        for col, (h, label) in enumerate(_HALVES):
            meas = getattr(pair, h)[zi, b].double().numpy()
            nom = nominal[h][zi, b]
            top = float(max(meas.max(), nom.max(), 1e-30))
            norm = LogNorm(vmin=top * 1e-4, vmax=top)
            lam = f"{pair.wavelengths[b] * 1e9:.4g} nm"
            res = meas - nom
            lim = float(max(np.abs(res).max(), 1e-30))
            panels = ((meas, f"measured, {label}, {lam}\nlog scale {top * 1e-4:.1e} … {top:.1e}", norm, "inferno"),
                      (nom, f"nominal, {label}, {lam}\nlog scale {top * 1e-4:.1e} … {top:.1e}", norm, "inferno"),
                      (res, f"measured − nominal, {label}\nblue −{lim:.1e} … red +{lim:.1e}", None, "RdBu_r"))
            for j, (img, title, nrm, cmap) in enumerate(panels):
                ax = axes[row, 3 * col + j]
                shown = np.maximum(img, norm.vmin) if nrm is not None else img
                ax.imshow(shown, extent=ext, norm=nrm, vmin=None if nrm else -lim, vmax=None if nrm else lim,
                          cmap=cmap, origin="upper", interpolation="nearest")
                ax.set_title(title, fontsize=6.5)
                ax.set_xticks([])
                ax.set_yticks([])
    fig.suptitle(f"plane z = {_depth(pair.depths[zi])}; each panel {2 * half_um:.4g} µm square (x right, y up), "
                 f"values: fraction of the whole aperture's light per pixel", fontsize=9)
    fig.subplots_adjust(wspace=0.45, hspace=0.55, left=0.04, right=0.99, top=1 - 1.0 / fig.get_figheight(),
                        bottom=0.06)
    return figure_html(fig, f"measured and nominal PSFs at {_depth(pair.depths[zi])}")


def _ee_figure(pair, nominal: dict) -> str:
    """Encircled energy, measured (solid) against nominal (dashed), one panel per plane and half."""
    plt = _plt()
    nz = len(pair.depths)
    fig, axes = plt.subplots(nz, 2, figsize=(10, 3 * nz), squeeze=False)
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(pair.wavelengths)))
    um = pair.sensor_pitch * 1e6
    for zi in range(nz):
        for col, (h, label) in enumerate(_HALVES):
            ax = axes[zi, col]
            for b in _shown_bands(len(pair.wavelengths)):
                r, ee = encircled_energy(getattr(pair, h)[zi, b].double().numpy())
                _, ee_n = encircled_energy(nominal[h][zi, b])
                ax.plot(r * um, ee, color=colors[b], label=f"{pair.wavelengths[b] * 1e9:.4g} nm")
                ax.plot(r * um, ee_n, color=colors[b], ls="--")
            ax.set_title(f"{label}, z = {_depth(pair.depths[zi])} (solid measured, dashed nominal)", fontsize=8)
            ax.set_xlabel("radius from the chief ray (µm)", fontsize=7)
            ax.set_ylabel("fraction of the kernel's light", fontsize=7)
            ax.set_ylim(0, 1.02)
            ax.tick_params(labelsize=6)
            ax.legend(fontsize=6)
    fig.subplots_adjust(wspace=0.25, hspace=0.45, left=0.07, right=0.98, top=0.92, bottom=0.12)
    return figure_html(fig, "encircled energy")


def _crosstalk_figure(walls: dict) -> str:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 3))
    fig.subplots_adjust(left=0.07, right=0.98, top=0.88, bottom=0.16)
    cols = np.arange(walls["alpha_lr"].size)
    for key, label in (("alpha_lr", "α l→r (plain view's light on the coded photodiode)"),
                       ("alpha_rl", "α r→l (coded view's light on the plain photodiode)")):
        a, se = walls[key], walls[key + "_se"]
        ax.plot(cols, a, label=label)
        ax.fill_between(cols, a - se, a + se, alpha=0.3)
    ax.set_xlabel("sensor column (px)", fontsize=7)
    ax.set_ylabel("crosstalk ratio (fraction)", fontsize=7)
    ax.set_title(f"per-column crosstalk ± 1 standard error ({walls['rows']} rows)", fontsize=8)
    ax.legend(fontsize=7)
    ax.tick_params(labelsize=6)
    return figure_html(fig, "crosstalk profile")


def _table(head: list[str], rows: list[list[str]]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _num(v, fmt: str = ".4g", none: str = "—") -> str:
    return none if v is None else format(v, fmt)


def _photons(r: dict) -> str:
    """The detected photons with their relative standard error, or why they are not stated."""
    if r["photons"] is None:
        return "— (one frame, no shot noise, or too few frames to fit the photon transfer within ±50 %)"
    return f"{r['photons']:.3g} ± {100 * r['photons_rel_se']:.0f} %"


def _recordings_table(rows: list[dict]) -> str:
    head = ["recording", "half", "depth", "band(s)", "frames / darks", "exposure (s)", "shift rows, columns (px)",
            "signal (DN)", "photons (detected)", "SNR of the kernel's sum", "peak SNR", "noise from"]
    out = []
    for r in rows:
        band = "R, G, B" if r["channels"] == "rgb" else f"{r['wavelength_m'] * 1e9:.4g} nm"
        out.append([r["recording"], r["half"], _depth(r["depth_m"]), band, f"{r['frames']} / {r['darks']}",
                    _num(r["exposure_s"]), f"{r['shift_px'][0]:+.2f}, {r['shift_px'][1]:+.2f}",
                    _num(r["signal_dn"]), _photons(r),
                    _num(r["snr"], ".3g"), _num(r["peak_snr"], ".3g"), r["noise"]])
    return _table(head, out)


def _residual_table(pair, nominal: dict) -> str:
    out = []
    for zi, z in enumerate(pair.depths):
        for b, w in enumerate(pair.wavelengths):
            cells = [_depth(z), f"{w * 1e9:.4g} nm"]
            for h, _ in _HALVES:
                m, n = getattr(pair, h)[zi, b].double().numpy(), nominal[h][zi, b]
                cells += [f"{float(m.sum()):.4f}", f"{float(np.abs(m - n).sum() / max(n.sum(), 1e-30)):.3f}"]
            out.append(cells)
    return _table(["depth", "band", "coded: light in kernel", "coded: Σ|measured − nominal| / Σ nominal",
                   "plain: light in kernel", "plain: Σ|measured − nominal| / Σ nominal"], out)


_STYLE = ("body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em;color:#222}"
          "table{border-collapse:collapse;font-size:0.85em;margin:0.5em 0}td,th{border:1px solid #ccc;"
          "padding:2px 6px;text-align:right}th{background:#f3f3f3}img{max-width:100%}code{font-size:0.9em}")


def write_report(path, pair, nominal: dict, rows: list[dict], walls: dict | None, provenance: dict,
                 warnings=()):
    """Write ``calibration.html`` atomically: ``pair`` the calibrated PSFs, ``nominal`` {half: array} the design's
    on the same grid, ``rows`` the recordings' summaries, ``walls`` the crosstalk (or None), ``warnings`` (each a
    sentence, shown first). Returns the path."""
    k = pair.coded.shape[-1]
    n_planes, n_bands = len(pair.depths), len(pair.wavelengths)
    parts = [f"<h1>Calibration of a fabricated part</h1><p>{len(rows)} point-source recordings give both halves' "
             f"PSFs at {n_planes} plane{'s' * (n_planes > 1)} × {n_bands} band{'s' * (n_bands > 1)} on the design's "
             f"{k} × {k}-pixel kernel ({k * pair.sensor_pitch * 1e6:.4g} µm square, pixel pitch "
             f"{pair.sensor_pitch * 1e6:.4g} µm). Each is registered to the design's nominal PSF (the shift is the "
             f"source's or the sensor's offset, not a fab error) and scaled to the nominal half's share of the light "
             f"in the kernel: the recordings cannot know the absolute energy. "
             + ("" if walls is None else
                f"Crosstalk from the white-wall pairs: mean α l→r = {np.mean(walls['alpha_lr']):.4f}, α r→l = "
                f"{np.mean(walls['alpha_rl']):.4f} over {walls['alpha_lr'].size} columns.") + "</p>",
             *(f"<p><strong>Warning:</strong> {html.escape(w)}.</p>" for w in warnings),
             "<h2>Recordings</h2>", _recordings_table(rows),
             "<p>Shift: from the frame's centre pixel to the chief ray, rows down and columns right. Photons: the "
             "window's signal over the conversion gain that the frames' photon transfer (variance against signal) "
             "gives. SNR: the kernel window's summed signal over the noise of that sum, measured from the frames.</p>",
             "<h2>Measured against nominal</h2>", _residual_table(pair, nominal)]
    if n_bands > MAX_BANDS:
        parts.append(f"<p>The figures show {MAX_BANDS} of the {n_bands} bands, evenly spaced.</p>")
    parts += [_plane_figure(pair, nominal, zi) for zi in range(n_planes)]
    parts += ["<h2>Encircled energy</h2>", _ee_figure(pair, nominal)]
    if walls is not None:
        parts += ["<h2>Crosstalk</h2>", _crosstalk_figure(walls),
                  f"<p>Standard errors: the row-to-row scatter of the pixels' ratios in a column over √rows; median "
                  f"{np.median(walls['alpha_lr_se']):.2g} (l→r) and {np.median(walls['alpha_rl_se']):.2g} "
                  f"(r→l).</p>"]
    prov = [[k_, str(v) if not isinstance(v, list) else f"{len(v)} values"] for k_, v in provenance.items()]
    parts += ["<h2>Provenance</h2>", _table(["key", "value"], prov)]
    page = (f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>doefab calibration</title>"
            f"<style>{_STYLE}</style></head><body>{''.join(parts)}</body></html>\n")
    return atomic_write_text(path, page)

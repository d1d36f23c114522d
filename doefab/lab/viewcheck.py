"""Whether a part's PSF recordings are of the halves and the orientation their recordings file states: each
recording registered, cut and scaled to the design's PSFs of its stated half (as the calibration does), to the other
half's (the coded and plain recordings swapped) and to its stated half's mirrored left–right (frames flipped, e.g. by
a raw converter), and the calibration warned of where another template fits clearly better. A fit's measure:
Σ|registered recording − template| / Σ template over the recording's entries.
"""

from __future__ import annotations

import math

import numpy as np

from doefab.errors import DoefabError
from doefab.lab.measure import extract, normalise, register

__all__ = ["template_fits", "view_warnings", "clearly_better", "VIEW_MISMATCH", "VIEW_MARGIN"]

VIEW_MISMATCH = 0.5  # another template fits at most this fraction as far off as the stated one: warned of
VIEW_MARGIN = 0.05  # ... and closer by more than this share of the light (not a difference within the noise)


def clearly_better(stated: float, other: float, ratio: float, margin: float) -> bool:
    """Whether an alternative reading that is ``other`` off fits clearly better than the stated one, ``stated`` off:
    at most ``ratio`` as far off and closer by more than ``margin`` (not a difference within the noise). False
    where either is NaN.

    Example: ``clearly_better(0.6, 0.1, VIEW_MISMATCH, VIEW_MARGIN)`` is True."""
    return bool(other <= ratio * stated and stated - other > margin)


def template_fits(chans, wide_refs, other_wide, k: int) -> dict:
    """{"stated", "swapped", "mirrored"}: how far off a recording's channels ``chans`` fit each template when
    registered, cut to the ``k``-pixel kernel and scaled as the calibration does (:func:`_fit_off`). ``wide_refs``,
    ``other_wide``: the stated and the other half's PSFs over the registration's wider window.

    Example: ``template_fits(chans, wide, other, 31)["stated"]`` is 0 for a noiseless recording of the stated half."""
    return {"stated": _fit_off(chans, wide_refs, k), "swapped": _fit_off(chans, other_wide, k),
            "mirrored": _fit_off(chans, [w[..., ::-1] for w in wide_refs], k)}


def _off(psfs, refs) -> float:
    """Σ|psf − ref| / Σ ref over every entry."""
    return float(sum(np.abs(p - r).sum() for p, r in zip(psfs, refs))
                 / max(sum(float(r.sum()) for r in refs), 1e-30))


def _fit_off(chans, wide_refs, k: int) -> float:
    """How far off the recording's channels ``chans`` fit templates ``wide_refs`` (over the registration's window)
    when registered, cut and scaled to them as the stated ones are (:func:`_off`); inf where they cannot be."""
    c = (wide_refs[0].shape[-1] - k) // 2
    refs = [w[c:c + k, c:c + k] for w in wide_refs]
    try:
        chief = register(np.sum(chans, axis=0), np.sum(wide_refs, axis=0), kernel=k)
        return _off([normalise(extract(ch, chief, k), float(ref.sum()), "") for ch, ref in zip(chans, refs)], refs)
    except (DoefabError, ValueError, IndexError):
        return math.inf


def view_warnings(rows: list[dict]) -> list[str]:
    """Where a half's recordings fit another template better than the design's PSFs of the half the recordings file
    states: each recording registered, cut and scaled to the stated half's PSFs, to the other half's (the coded and
    plain recordings swapped) and to the stated half's mirrored left–right (frames flipped), ``template_fit`` of
    ``calibrate.calibrate_recording`` (:func:`template_fits`), averaged over a half's recordings; warned of
    where another fits at most half as far off and closer by more than 5 % of the light.

    Example: ``view_warnings(rows) == []`` for recordings of the halves their file states."""
    out = []
    for half in ("coded", "plain"):
        fits = [r["template_fit"] for r in rows if r["half"] == half and "template_fit" in r]
        if not fits:
            continue
        total = {k: float(np.mean([f[k] for f in fits])) for k in fits[0]}
        alts = {f"the design's {'plain' if half == 'coded' else 'coded'} half (the coded and plain recordings "
                f"swapped? check each [[psf]]'s half and view)": total["swapped"],
                "the design's mirrored left–right (the frames flipped? check the camera's or the raw converter's "
                "orientation)": total["mirrored"]}
        what, best = min(alts.items(), key=lambda kv: kv[1])
        if clearly_better(total["stated"], best, VIEW_MISMATCH, VIEW_MARGIN):
            out.append(f"the {half} recordings, registered to the design's {half} half, are off by "
                       f"{total['stated']:.0%} (Σ|measured − nominal| / Σ nominal), but registered to {what} by "
                       f"{best:.0%}")
    return out

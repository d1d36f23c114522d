"""``crosstalk.json``: a dual-pixel sensor's per-column crosstalk as calibrated (Eq. 30–31), versioned.

``{"format": "doefab-crosstalk", "version": 1, "columns": W, "alpha_lr": [...], "alpha_rl": [...],
"alpha_lr_se": [...], "alpha_rl_se": [...], ...}``: per sensor column (left to right) the fraction α_l→r of the
left (plain-half) view's light that lands on the right (coded-half) photodiode, α_r→l the other way (Eq. 29), and
their standard errors (fractions too); any further keys say where the calibration comes from.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.imaging.crossratios import check_pair
from doefab.io import atomic_write_text

__all__ = ["save_crosstalk", "read_crosstalk", "FORMAT", "VERSION"]

FORMAT, VERSION = "doefab-crosstalk", 1
KEYS = ("alpha_lr", "alpha_rl", "alpha_lr_se", "alpha_rl_se")


def _profiles(values: dict, where: str) -> dict:
    """The four per-column lists as 1-D float arrays of one length, checked: ratios a dual-pixel sensor can have
    (``crossratios.check_pair``), standard errors finite and ≥ 0."""
    out = {}
    for k in KEYS:
        try:
            out[k] = np.asarray(values[k], dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise DoefabError(f"{where}: {k} must be a list of numbers, one per sensor column") from None
    n = {k: v.size for k, v in out.items()}
    if len(set(n.values())) != 1 or not out["alpha_lr"].size:
        raise DoefabError(f"{where}: {', '.join(KEYS)} must be non-empty and of one length (one value per sensor "
                          f"column), got lengths {n}")
    check_pair(out["alpha_lr"], out["alpha_rl"], f"{where}: alpha_lr, alpha_rl")
    for k in KEYS[2:]:
        if not np.all(np.isfinite(out[k])) or np.any(out[k] < 0):
            raise DoefabError(f"{where}: {k} must hold finite standard errors ≥ 0 (fractions)")
    return out


def save_crosstalk(path, alpha_lr, alpha_rl, se_lr, se_rl, meta: dict | None = None) -> Path:
    """Write ``crosstalk.json`` atomically (see the module docstring). ``meta``: anything JSON-able (e.g. the
    recordings' SHA-256), which may not reuse the calibration's own keys. Returns the path."""
    p = _profiles({"alpha_lr": alpha_lr, "alpha_rl": alpha_rl, "alpha_lr_se": se_lr, "alpha_rl_se": se_rl},
                  "crosstalk")
    meta = dict(meta or {})
    clash = sorted(set(meta) & {"format", "version", "columns", *KEYS})
    if clash:
        raise DoefabError(f"crosstalk meta may not set {clash}: those keys hold the calibration itself; rename them")
    record = {"format": FORMAT, "version": VERSION, "columns": int(p["alpha_lr"].size),
              **{k: v.tolist() for k, v in p.items()}, **meta}
    try:
        text = json.dumps(record, indent=1, allow_nan=False) + "\n"
    except (TypeError, ValueError) as exc:
        raise DoefabError(f"crosstalk meta must hold JSON values (strings, finite numbers, lists, dicts): {exc}") \
            from None
    return atomic_write_text(path, text)


def read_crosstalk(path) -> tuple[dict, dict]:
    """``(profiles, record)`` of a ``crosstalk.json``: the four per-column arrays checked, and the whole record.
    Refuses, naming the file, another format or version and lists that are missing, of unequal length or no
    crosstalk a dual-pixel sensor has."""
    path = Path(path)
    if not path.is_file():
        raise DoefabError(f"{path} not found: give the crosstalk.json that doefab calibrate wrote")
    with open(path, "rb") as f:
        zipped = f.read(2) == b"PK"  # a zip: a numpy .npz archive such as psf_pair.npz
    if zipped:
        raise DoefabError(f"{path} is a numpy archive, not a crosstalk file (JSON): give the crosstalk.json that "
                          f"doefab calibrate wrote (a psf_pair.npz goes to --psf)")
    try:
        rec = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise DoefabError(f"{path} is not valid JSON ({exc}): write it again with doefab calibrate") from None
    if not isinstance(rec, dict) or rec.get("format") != FORMAT:
        got = rec.get("format") if isinstance(rec, dict) else None
        raise DoefabError(f"{path} is not a {FORMAT} file (its format is {got!r}): give the crosstalk.json that "
                          f"doefab calibrate wrote")
    if rec.get("version") != VERSION:
        raise DoefabError(f"{path}: version {rec.get('version')!r}; this doefab reads version {VERSION}: write it "
                          f"again with this doefab (doefab calibrate)")
    missing = [k for k in ("columns", *KEYS) if k not in rec]
    if missing:
        raise DoefabError(f"{path} lacks the keys {missing}: write it again with doefab calibrate")
    p = _profiles(rec, str(path))
    if rec["columns"] != p["alpha_lr"].size:
        raise DoefabError(f"{path}: columns is {rec['columns']!r} but the lists hold {p['alpha_lr'].size} values: "
                          f"write it again with doefab calibrate")
    return p, rec

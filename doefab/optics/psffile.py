"""``psf_pair.npz``: a :class:`~doefab.optics.psf.PSFPair` on disk, versioned and checked when read.

The file is a numpy ``.npz`` archive (read with ``np.load(path, allow_pickle=False)``):

=================  ============================  =======================================================
key                type, shape                   content
=================  ============================  =======================================================
``format``         str                           ``"doefab-psf-pair"``
``version``        int                           ``1``
``coded``          float32 (D, W, K, K)          the coded half's PSF: energy fractions of the whole
                                                 aperture's light per sensor pixel (each half sums to
                                                 about 0.5 over a large kernel); rows = y (row 0 top),
                                                 pixel (K//2, K//2) on the chief ray
``uncoded``        float32 (D, W, K, K)          the plain half's, likewise
``wavelengths_m``  float64 (W,)                  the bands, metres
``depths_m``       float64 (D,)                  the source distances, metres (``inf``: a plane wave)
``sensor_pitch_m`` float64 scalar                the sensor's pixel pitch, metres
``provenance``     str (JSON object)             where the PSFs come from: ``source`` (``"calibrate"``,
                                                 ``"diagnose"`` or ``"simulation"``), ``levels_sha256``
                                                 of the design, ``recordings_sha256``, ``shifts_px``...
=================  ============================  =======================================================
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.io import atomic_write_bytes

__all__ = ["save_psf_pair", "read_psf_pair", "FORMAT", "VERSION"]

FORMAT = "doefab-psf-pair"
VERSION = 1
_KEYS = ("format", "version", "coded", "uncoded", "wavelengths_m", "depths_m", "sensor_pitch_m", "provenance")


def _as_array(v, name: str) -> np.ndarray:
    """A PSF half as a float32 numpy array, or one error naming it."""
    if v is None:
        raise DoefabError(f"the pair's {name} PSF is missing: psf_pair.npz holds both halves; compute the pair with "
                          f"halves=('coded', 'uncoded')")
    return np.asarray(v.detach().cpu().numpy() if hasattr(v, "detach") else v, dtype=np.float32)


def _problems(coded, uncoded, wavelengths, depths, pitch) -> list[str]:
    """What is wrong with a pair's arrays (shape, finiteness, sign, units), as phrases; [] when nothing."""
    out = []
    if coded.ndim != 4 or coded.shape[-1] != coded.shape[-2]:
        out.append(f"coded has shape {coded.shape}, not (depths, wavelengths, K, K)")
    if uncoded.shape != coded.shape:
        out.append(f"uncoded has shape {uncoded.shape}, coded {coded.shape}: the halves must match")
    if coded.ndim == 4 and wavelengths.shape != (coded.shape[1],):
        out.append(f"wavelengths_m has shape {wavelengths.shape}, the PSFs {coded.shape[1]} bands")
    if coded.ndim == 4 and depths.shape != (coded.shape[0],):
        out.append(f"depths_m has shape {depths.shape}, the PSFs {coded.shape[0]} planes")
    for name, a in (("coded", coded), ("uncoded", uncoded)):
        if not np.all(np.isfinite(a)):
            out.append(f"{name} holds {int(np.sum(~np.isfinite(a)))} NaN or infinite values")
        elif a.size and float(a.min()) < 0:
            out.append(f"{name} holds negative values (down to {float(a.min()):.3g}): PSFs are energy fractions ≥ 0")
    if wavelengths.size and not np.all((wavelengths >= 100e-9) & (wavelengths <= 20e-6)):
        out.append(f"wavelengths_m {wavelengths.tolist()} are not all in 100 nm – 20 µm (metres: 550 nm is 5.5e-07)")
    if np.any(np.isnan(depths)) or np.any(depths <= 0):
        out.append(f"depths_m {depths.tolist()} must be > 0 m (inf for a plane wave)")
    if pitch.shape != () or not math.isfinite(float(pitch)) or not 1e-7 <= float(pitch) <= 1e-3:
        out.append(f"sensor_pitch_m {pitch.tolist()!r} is not one pitch in metres (5.4 µm is 5.4e-06)")
    return out


def save_psf_pair(pair, path, provenance: dict | None = None) -> Path:
    """Write ``pair`` (a :class:`PSFPair` with both halves) to ``path`` (``psf_pair.npz``) atomically.

    ``provenance`` (default: ``pair.provenance``, else empty) is stored as a JSON object; keys in use:
    ``source`` ("calibrate" | "diagnose" | "simulation"), ``levels_sha256``, ``recordings_sha256``, ``shifts_px``.
    The PSFs are stored as float32 (a float32 pair reads back bit for bit). Refuses a pair that would not read
    back (a missing half, NaN, negative values, mismatched shapes) before anything is written.
    """
    coded, uncoded = _as_array(pair.coded, "coded"), _as_array(pair.uncoded, "uncoded")
    wavelengths = np.asarray(pair.wavelengths, dtype=np.float64).reshape(-1)
    depths = np.asarray(pair.depths, dtype=np.float64).reshape(-1)
    pitch = np.asarray(pair.sensor_pitch, dtype=np.float64)
    bad = _problems(coded, uncoded, wavelengths, depths, pitch)
    if bad:
        raise DoefabError(f"cannot save the PSF pair to {path}: " + "; ".join(bad))
    prov = provenance if provenance is not None else (getattr(pair, "provenance", None) or {})
    if not isinstance(prov, dict):
        raise DoefabError(f"provenance must be a dict (e.g. {{'source': 'calibrate'}}), got {type(prov).__name__}")
    try:
        prov_text = json.dumps(prov, allow_nan=False, sort_keys=True)
    except (TypeError, ValueError) as exc:
        raise DoefabError(f"provenance must hold JSON values (strings, finite numbers, lists, dicts): {exc}") from None
    buf = io.BytesIO()
    np.savez(buf, format=np.array(FORMAT), version=np.array(VERSION, dtype=np.int64), coded=coded, uncoded=uncoded,
             wavelengths_m=wavelengths, depths_m=depths, sensor_pitch_m=pitch, provenance=np.array(prov_text))
    return atomic_write_bytes(path, buf.getvalue())


def _read(path: Path) -> dict:
    """The archive's arrays, or one error naming the file."""
    if not path.is_file():
        raise DoefabError(f"{path} not found: give the psf_pair.npz that doefab calibrate (or diagnose) wrote")
    with open(path, "rb") as f:
        head = f.read(64)
    if not head.startswith(b"PK") and head.lstrip()[:1] in (b"{", b"["):  # a JSON file, not a numpy archive
        raise DoefabError(f"{path} is a JSON file, not a PSF pair (.npz): give the psf_pair.npz that doefab "
                          f"calibrate or diagnose wrote (a crosstalk.json goes to --crosstalk)")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in _KEYS if k not in z.files]
            if missing:
                raise DoefabError(f"{path} lacks the keys {missing}: not a {FORMAT} file (version {VERSION}); "
                                  f"write it with doefab calibrate or PSFPair.save")
            return {k: z[k] for k in _KEYS}
    except DoefabError:
        raise
    except (ValueError, OSError, EOFError, KeyError) as exc:  # not a zip, pickled objects, truncated
        raise DoefabError(f"{path} is not a readable .npz archive ({exc}): write it with doefab calibrate or "
                          f"PSFPair.save") from None


def read_psf_pair(path) -> dict:
    """Read ``psf_pair.npz`` (see the module docstring): the :class:`~doefab.optics.psf.PSFPair` fields it holds
    (``coded``, ``uncoded``: float32 CPU tensors; ``wavelengths``, ``depths``, ``sensor_pitch``; ``provenance``
    the stored dict), which ``PSFPair.load`` builds the pair from. Refuses, naming the file and the problem, a file of another format or
    version, a missing key, a wrong shape, NaN / infinite or negative PSF values and implausible units."""
    import torch

    path = Path(path)
    z = _read(path)
    fmt, ver = z["format"], z["version"]
    if fmt.shape != () or fmt.dtype.kind != "U" or str(fmt) != FORMAT:
        raise DoefabError(f"{path}: format is {fmt.tolist()!r}, not {FORMAT!r}: not a doefab PSF pair")
    if ver.shape != () or ver.dtype.kind not in "iu" or int(ver) != VERSION:
        raise DoefabError(f"{path}: version {ver.tolist()!r}; this doefab reads version {VERSION}: write it again "
                          f"with this doefab (doefab calibrate)")
    arrays = {}
    for k in ("coded", "uncoded", "wavelengths_m", "depths_m", "sensor_pitch_m"):
        if z[k].dtype.kind != "f":
            raise DoefabError(f"{path}: {k} has dtype {z[k].dtype}, not floating point")
        arrays[k] = z[k]
    bad = _problems(arrays["coded"], arrays["uncoded"], arrays["wavelengths_m"], arrays["depths_m"],
                    arrays["sensor_pitch_m"])
    if bad:
        raise DoefabError(f"{path}: " + "; ".join(bad) + ": the file is corrupt; write it again (doefab calibrate)")
    try:
        prov = json.loads(str(z["provenance"]))
    except ValueError:
        prov = None
    if not isinstance(prov, dict):
        raise DoefabError(f"{path}: provenance is not a JSON object: write the file again (doefab calibrate)")
    return {"coded": torch.from_numpy(np.ascontiguousarray(arrays["coded"], np.float32)),
            "uncoded": torch.from_numpy(np.ascontiguousarray(arrays["uncoded"], np.float32)),
            "wavelengths": tuple(float(w) for w in arrays["wavelengths_m"]),
            "depths": tuple(float(d) for d in arrays["depths_m"]), "sensor_pitch": float(arrays["sensor_pitch_m"]),
            "provenance": prov}

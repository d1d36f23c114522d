"""Camera RGB spectral sensitivities: the published curves doefab knows by name, or a user's own CSV file.

Named curves (all shipped by the ``colour-science`` package):

- ``"Canon EOS 5D Mark II"`` (the default): measured for the Academy's rawtoaces project,
  ``colour/characterisation/datasets/rawtoaces/CANON_EOS_5DMark_II_RGB_Sensitivities.csv``, 380–780 nm at 5 nm.
  The paper's camera is a 5D Mark IV, whose curves are not published in any package; the Mark II is the nearest
  Canon full-frame sensor with public curves.
- ``"Nikon D5100"``: measured at the UK's National Physical Laboratory, ``colour.MSDS_CAMERA_SENSITIVITIES
  ["Nikon 5100 (NPL)"]``, 380–780 nm at 5 nm.
- ``"Sigma SD Merrill"``: NPL, ``colour.MSDS_CAMERA_SENSITIVITIES["Sigma SDMerill (NPL)"]`` (a Foveon sensor),
  400–680 nm at 10 nm: bands beyond 680 nm are refused.

Neither the D5100 nor the SD Merrill has dual-pixel photodiodes: like the Mark II for the prototype's Mark IV,
they stand in for a dual-pixel sensor of similar colour filters. The NPL curves are published normalised to a
peak of 1 per channel, so their channels' relative gains (which channel clips first under white light) are the
dataset's, not the camera's; the rawtoaces curves keep them. A user's own measured curves (a CSV) keep whatever
gains they were measured with.

A CSV file (anything else is read as a path): a header line, then rows ``wavelength_nm, R, G, B`` in
increasing wavelength (each wavelength once), relative sensitivities ≥ 0 (any scale, up to the largest float:
``imaging.sensor.sensor_response`` normalises). Blank lines and ``#`` comments are skipped. The file is read as
UTF-8 (a spreadsheet's byte-order mark dropped), as UTF-16 when it starts with that byte-order mark, and as
Latin-1 otherwise (a header such as ``Wellenlänge (nm)`` written by a Windows tool). A row that breaks a rule is
named by its line number. Measured curves often dip slightly below zero in their tails: values down to −1 % of a
channel's peak are read as 0; below that the file is refused.
"""

from __future__ import annotations

import codecs
import functools
import hashlib
import math
import os
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError

__all__ = ["DEFAULT_RESPONSE", "RESPONSES", "response_curves", "response_sha256", "response_label", "is_named"]

DEFAULT_RESPONSE = "Canon EOS 5D Mark II"
RESPONSES = {  # name → where colour-science keeps the curves
    "Canon EOS 5D Mark II": "rawtoaces CANON_EOS_5DMark_II_RGB_Sensitivities.csv",
    "Nikon D5100": "MSDS_CAMERA_SENSITIVITIES['Nikon 5100 (NPL)']",
    "Sigma SD Merrill": "MSDS_CAMERA_SENSITIVITIES['Sigma SDMerill (NPL)']",
}
_MSDS = {"Nikon D5100": "Nikon 5100 (NPL)", "Sigma SD Merrill": "Sigma SDMerill (NPL)"}


def _colour_curves(name: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        import colour
        from colour.characterisation.aces_it import ROOT_RESOURCES_RAWTOACES
    except ImportError:
        raise DoefabError("camera responses need the colour-science package: pip install colour-science") from None
    if name == DEFAULT_RESPONSE:
        path = os.path.join(ROOT_RESOURCES_RAWTOACES, "CANON_EOS_5DMark_II_RGB_Sensitivities.csv")
        data = np.genfromtxt(path, delimiter=",", names=True)
        return (np.asarray(data["wavelength"], np.float64) * 1e-9,
                np.stack([np.asarray(data[c], np.float64) for c in ("R", "G", "B")]))
    msds = colour.MSDS_CAMERA_SENSITIVITIES[_MSDS[name]]
    cols = [list(msds.labels).index(c) for c in ("red", "green", "blue")]
    return np.asarray(msds.wavelengths, np.float64) * 1e-9, np.asarray(msds.values, np.float64)[:, cols].T.copy()


def _csv_curves(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths in metres, [3, L]) of a ``wavelength_nm, R, G, B`` CSV, or one error naming the fix."""
    if not path.is_file():
        names = ", ".join(f'"{n}"' for n in RESPONSES)
        near = [n for n in RESPONSES if n.lower() == path.name.strip().lower()]
        fix = f'write "{near[0]}" (a camera\'s name as listed)' if near else _FIX
        raise DoefabError(f"camera response {str(path)!r} is neither a known camera ({names}) nor an existing CSV "
                          f"file: {fix}")
    lines, data = _csv_rows(path)
    lam_nm, curves = data[:, 0], data[:, 1:].T
    for unit, top, factor in (("metres", 1e-3, 1e9), ("micrometres", 3.0, 1e3)):
        if lam_nm.max() < top:
            raise DoefabError(f"{path}: wavelengths {lam_nm.min():g}–{lam_nm.max():g} look like {unit}: write "
                              f"nanometres (e.g. {lam_nm.max() * factor:.4g})")
    _check_wavelengths(path, lam_nm, lines)
    peak = curves.max(axis=1, keepdims=True)
    if np.any(peak <= 0) or np.any(curves < -0.01 * peak):
        raise DoefabError(f"{path}: sensitivities must be ≥ 0 (tails down to −1 % of a channel's peak are read as "
                          f"0) with some light in each of R, G and B")
    return lam_nm * 1e-9, np.clip(curves, 0.0, None)


_FIX = "give a CSV with a header line, then rows wavelength_nm, R, G, B (relative sensitivities ≥ 0)"


def _text(path: Path) -> str:
    """The file's text: UTF-8 (a spreadsheet's byte-order mark dropped), UTF-16 with its byte-order mark, else
    Latin-1 — the header is only a label and the rows are numbers, which every one of these spells alike."""
    raw = path.read_bytes()
    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        return raw.decode("utf-16")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _csv_rows(path: Path) -> tuple[list[int], np.ndarray]:
    """(the line number of each data row, [rows, 4] float64) of the file's rows after its header line; blank
    lines and ``#`` comments are skipped."""
    text = _text(path)
    first = text.splitlines()[:1]
    if first and _numbers(first[0]):
        raise DoefabError(f"{path}: its first line ({first[0][:40]!r}) is data, not a header: add a header line "
                          f"such as wavelength_nm,R,G,B")
    lines, rows = [], []
    for n, line in enumerate(text.splitlines()[1:], start=2):
        cells = [c.strip() for c in line.split("#")[0].split(",")]
        if cells == [""]:
            continue
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            raise DoefabError(f"{path}: not a readable CSV of numbers (line {n}: {line.strip()[:40]!r}): "
                              f"{_FIX}") from None
        if len(cells) != 4:
            raise DoefabError(f"{path}: line {n} has {len(cells)} column(s); need 4 on every row: {_FIX}")
        if not all(math.isfinite(v) for v in rows[-1]):
            raise DoefabError(f"{path}: line {n} holds NaN or infinite values ({line.strip()[:40]!r}): {_FIX}")
        lines.append(n)
    if len(rows) < 2:
        raise DoefabError(f"{path}: {len(rows)} row(s) of data; need ≥ 2 rows of 4 columns: {_FIX}")
    return lines, np.asarray(rows, np.float64)


def _check_wavelengths(path: Path, lam_nm: np.ndarray, lines: list[int]) -> None:
    """Wavelengths within 200–2000 nm, each once, in increasing order; the error names the line."""
    out = np.flatnonzero((lam_nm < 200) | (lam_nm > 2000))
    if out.size:
        i = int(out[0])
        raise DoefabError(f"{path}: line {lines[i]}: wavelength {lam_nm[i]:g} nm lies outside 200–2000 nm: "
                          f"wavelengths are in nanometres, within the range a camera's sensitivity is measured in")
    bad = np.flatnonzero(np.diff(lam_nm) <= 0)
    if bad.size:
        i = int(bad[0])
        what = "repeats" if lam_nm[i + 1] == lam_nm[i] else "is below"
        raise DoefabError(f"{path}: line {lines[i + 1]}: wavelength {lam_nm[i + 1]:g} nm {what} line "
                          f"{lines[i]}'s {lam_nm[i]:g} nm: wavelengths must increase row by row, each once (sort "
                          f"the rows by wavelength and keep one row per wavelength)")


def _numbers(line: str) -> bool:
    try:
        [float(v) for v in line.split(",")]
    except ValueError:
        return False
    return True


def response_curves(source: str | os.PathLike = DEFAULT_RESPONSE) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths in metres [L], R, G, B sensitivities [3, L]) of a named camera or a CSV file."""
    if not isinstance(source, (str, os.PathLike)) or not str(source):
        raise DoefabError(f"a camera response is a camera name ({', '.join(RESPONSES)}) or a CSV path, got {source!r}")
    if is_named(source):
        return _colour_curves(str(source))
    return _csv_curves(Path(source))


def is_named(source) -> bool:
    """Whether ``source`` names one of the cameras of ``RESPONSES`` (else it is a CSV path)."""
    return isinstance(source, str) and source in RESPONSES


def response_sha256(source: str | os.PathLike = DEFAULT_RESPONSE) -> str:
    """SHA-256 of the curves' values (wavelengths and sensitivities as float64): a response's identity, so a
    copied or renamed CSV is the same camera and an edited one is not."""
    p = Path(source) if not is_named(source) and isinstance(source, (str, os.PathLike)) else None
    stamp = (p.stat().st_mtime_ns, p.stat().st_size) if p is not None and p.is_file() else None
    return _sha_cached(str(source), stamp)


@functools.lru_cache(maxsize=32)
def _sha_cached(source: str, stamp) -> str:  # keyed by a file's time and size: an edited file is read again
    lam, curves = response_curves(source)
    return hashlib.sha256(lam.astype(np.float64).tobytes() + curves.astype(np.float64).tobytes()).hexdigest()


def response_label(source: str | os.PathLike) -> str:
    """How a report names a response: the camera, or the CSV's file name."""
    return str(source) if str(source) in RESPONSES else f"{Path(source).name} (CSV)"

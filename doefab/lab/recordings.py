"""The recordings file (TOML): what a lab recorded of its fabricated part, read and checked before any work.

Schema (paths relative to the file; globs allowed; every key below, nothing else)::

    design = "path/to/design"      # the design folder (or a mask set holding design/); --design overrides it
    pixel_format = "auto"          # auto | npy | png | tiff | raw (doefab.lab.frames)
    black_level = 0                # DN subtracted from frames without dark frames (0: a raw's own, per channel)
    white_level = 4095             # optional: the DN where the sensor clips (default: the file's full scale)
    [[psf]]                        # one point-source recording
    half = "coded"                 # the aperture half that was open: coded | plain
    view = "coded"                 # the dual-pixel view the frames are: coded (right) | plain (left)
    depth_m = 5.0                  # source distance in metres, or inf ("inf")
    wavelength_nm = 550            # a narrow-band source, monochrome frames ... (xor)
    channels = "rgb"               # ... a broadband source, colour frames, one PSF per channel (3-band designs)
    frames = ["psf/coded_*.tiff"]
    dark = ["psf/dark_*.tiff"]     # optional
    exposure_s = 0.01              # optional, reported
    [[wall]]                       # a white-wall pair for the crosstalk calibration (Eq. 30-31)
    half = "coded"
    coded_view = ["wall/c_*.tiff"]
    plain_view = ["wall/p_*.tiff"]
    dark = ["wall/dark_*.tiff"]    # optional
    exposure_s = 0.01              # optional

:func:`load_recordings` refuses a malformed file with every problem and its key; :func:`recording_problems`
reads every frame and lists what a calibration could not use (``doefab.lab.framechecks`` measures the photons).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path

from doefab.validate import distance_or_inf, unit_hint
from doefab.errors import DoefabError
from doefab.io import read_toml
from doefab.lab.frames import PIXEL_FORMATS, expand

__all__ = ["Recordings", "PSFRecording", "WallRecording", "load_recordings", "recording_problems",
           "check_recordings", "recordings_sha256", "band_index", "plane_index", "HALVES", "WAVELENGTH_TOL_M",
           "DEPTH_TOL"]

HALVES = ("coded", "plain")
WAVELENGTH_TOL_M = 1e-9  # a narrow-band source's wavelength within 1 nm of a design band
DEPTH_TOL = 0.01  # a source distance within 1 % of a design plane (inf only at inf)
_TOP = ("design", "pixel_format", "black_level", "white_level", "psf", "wall")
_PSF = ("half", "view", "depth_m", "wavelength_nm", "channels", "frames", "dark", "exposure_s")
_WALL = ("half", "coded_view", "plain_view", "dark", "exposure_s")


@dataclass
class PSFRecording:
    """One point-source recording: ``index`` (1-based, the file's order), the open ``half`` and the ``view``
    recorded (``coded`` | ``plain``), ``depth_m`` (metres, inf allowed), ``wavelength_m`` (metres, narrow-band)
    or ``channels`` (``"rgb"``), the ``frames`` and ``dark`` files, ``exposure_s`` (seconds or None)."""

    index: int
    half: str
    view: str
    depth_m: float
    wavelength_m: float | None
    channels: str | None
    frames: list[Path]
    dark: list[Path] = field(default_factory=list)
    exposure_s: float | None = None

    @property
    def name(self) -> str:
        return f"[[psf]] {self.index}"


@dataclass
class WallRecording:
    """One white-wall pair: the open ``half``, the frames of each view, the dark frames, ``exposure_s``."""

    index: int
    half: str
    coded_view: list[Path]
    plain_view: list[Path]
    dark: list[Path] = field(default_factory=list)
    exposure_s: float | None = None

    @property
    def name(self) -> str:
        return f"[[wall]] {self.index}"


@dataclass
class Recordings:
    """A recordings file read: its ``path``, its folder ``base``, the ``design`` folder (None when neither the file
    nor the caller names one), ``pixel_format``, ``black_level`` (DN), the ``psf`` and ``wall`` recordings, and
    ``white_level`` (DN where the sensor clips; None: each file's full scale)."""

    path: Path
    base: Path
    design: Path | None
    pixel_format: str
    black_level: float
    psf: list[PSFRecording]
    wall: list[WallRecording]
    white_level: float | None = None

    def files(self) -> list[Path]:
        """Every frame file, in the file's order (each recording's frames, then its dark frames)."""
        out: list[Path] = []
        for r in self.psf:
            out += r.frames + r.dark
        for w in self.wall:
            out += w.coded_view + w.plain_view + w.dark
        return out


class _Table:
    """One table of the file being read: typed getters that note a problem (with the key) instead of raising."""

    def __init__(self, table, where: str, allowed: tuple, base: Path, problems: list):
        self.t, self.where, self.base, self.problems = table, where, base, problems
        kind = where.split(" ")[0] if where else "the recordings file"
        for key in table:
            if key not in allowed:
                self.bad(key, f" is not a key of {kind}: the keys are {', '.join(allowed)}")

    def bad(self, key: str, text: str) -> None:
        """Note a problem: ``text`` follows the table and the key (`` = …``, `` is missing: …``)."""
        self.problems.append(f"{self.where + ' ' if self.where else ''}{key}{text}")

    def choice(self, key: str, allowed: tuple, default=None):
        v = self.t.get(key, default)
        if v is None:
            self.bad(key, f" is missing: give one of {', '.join(map(repr, allowed))}")
        elif v not in allowed:
            self.bad(key, f" = {v!r} is not one of {', '.join(map(repr, allowed))}")
            return None
        return v

    def number(self, key: str, lo: float, unit: str, *, required: bool, lo_open: bool = True):
        v = self.t.get(key)
        if v is None:
            if required:
                self.bad(key, f" is missing: give a number in {unit}")
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or math.isinf(v) \
                or (v <= lo if lo_open else v < lo):
            self.bad(key, f" = {v!r} must be a finite number {'>' if lo_open else '≥'} {lo:g} ({unit})")
            return None
        return float(v)

    def files(self, key: str, required: bool = True) -> list[Path]:
        if not required and self.t.get(key) == []:  # dark = []: no dark frames
            return []
        if key not in self.t:
            if required:
                self.bad(key, " is missing: give a file pattern or a list of them, e.g. [\"psf/frame_*.tiff\"]")
            return []
        try:
            return expand(self.t[key], self.base, f"{self.where + ' ' if self.where else ''}{key}")
        except DoefabError as exc:
            self.problems.append(str(exc))
            return []


def _depth(tab: _Table):
    v = tab.t.get("depth_m")
    d = distance_or_inf(v)
    if v is None:
        tab.bad("depth_m", " is missing: give the source distance in metres, or \"inf\"")
    elif d is None or d <= 0:
        tab.bad("depth_m", f" = {v!r} must be a distance > 0 in metres, or \"inf\"")
    return d if d is not None and d > 0 else None


def _wavelength(tab: _Table) -> tuple:
    """(wavelength_m, channels) of a [[psf]] table: exactly one of wavelength_nm, channels = "rgb"."""
    has_w, has_c = "wavelength_nm" in tab.t, "channels" in tab.t
    if has_w == has_c:
        tab.bad("wavelength_nm and channels", ": give exactly one, wavelength_nm = 550 (a narrow-band source, "
                                 "monochrome frames) or channels = \"rgb\" (a broadband source, colour frames)")
        return None, None
    if has_c:
        return None, tab.choice("channels", ("rgb",))
    nm = tab.number("wavelength_nm", 0.0, "nm", required=True)
    if nm is not None and not 100 <= nm <= 20000:
        tab.bad("wavelength_nm", f" = {nm:g} is outside 100–20000 nm{unit_hint(nm, 100, 20000, 'nm')}")
        return None, None
    return (None if nm is None else nm * 1e-9), None


def _design(raw: dict, design, base: Path, problems: list) -> Path | None:
    from doefab.design.design import committed_name, design_folder_of, designs_inside_hint

    if design is None and "design" in raw:
        if not isinstance(raw["design"], str) or not raw["design"]:
            problems.append(f"design = {raw['design']!r} must be the path of the design folder (a string)")
            return None
        design = (base / raw["design"]).resolve()
        named = committed_name(raw["design"])
        if named and not design.exists():  # a committed design by its name, nothing of that name beside the file
            from doefab.design.committed import committed_dir

            design = committed_dir(named)
    if design is None:
        return None
    d = design_folder_of(design)
    if not (d / "design.json").is_file():
        problems.append(f"design: {d} is not a design folder (no design.json): give the folder the part was made "
                        f"from (a mask set's design/), in the file or with --design{designs_inside_hint(d)}")
    return d


def load_recordings(path: str | Path, design: str | Path | None = None) -> Recordings:
    """Read and check a recordings file; ``design`` overrides its ``design`` key. One DoefabError lists every
    problem with its key (unknown keys, missing or invalid values, patterns that match no file)."""
    path = Path(path)
    raw = read_toml(path, "recordings file")
    base = path.resolve().parent
    problems: list[str] = []
    top = _Table(raw, "", _TOP, base, problems)
    fmt = top.choice("pixel_format", PIXEL_FORMATS, "auto")
    black = top.number("black_level", 0.0, "DN", required=False, lo_open=False)
    white = top.number("white_level", 0.0, "DN", required=False)
    if white is not None and black is not None and white <= black:
        top.bad("white_level", f" = {white:g} DN must be above black_level ({black:g} DN)")
    design_dir = _design(raw, design, base, problems)
    psf, wall = [], []
    for kind, keys in (("psf", _PSF), ("wall", _WALL)):
        tables = raw.get(kind, [])
        if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
            problems.append(f"{kind} must be tables written [[{kind}]], got {type(tables).__name__}")
            continue
        for i, t in enumerate(tables, 1):
            tab = _Table(t, f"[[{kind}]] {i}", keys, base, problems)
            half = tab.choice("half", HALVES)
            exposure = tab.number("exposure_s", 0.0, "seconds", required=False)
            if kind == "psf":
                view, depth, (wl, ch) = tab.choice("view", HALVES), _depth(tab), _wavelength(tab)
                psf.append(PSFRecording(i, half, view, depth, wl, ch, tab.files("frames"), tab.files("dark", False),
                                        exposure))
            else:
                wall.append(WallRecording(i, half, tab.files("coded_view"), tab.files("plain_view"),
                                          tab.files("dark", False), exposure))
    if not psf and not wall and not problems:
        problems.append("the file lists no recording: add [[psf]] tables (point sources) and [[wall]] tables "
                        "(white-wall pairs)")
    if problems:
        raise DoefabError(f"{path}: {len(problems)} problem{'s' * (len(problems) > 1)} in the recordings file:\n  - "
                          + "\n  - ".join(problems))
    return Recordings(path, base, design_dir, fmt, 0.0 if black is None else black, psf, wall, white)


def band_index(wavelength_m: float, wavelengths_m) -> int | None:
    """The design band within ``WAVELENGTH_TOL_M`` of ``wavelength_m`` (the nearest), or None."""
    best = min(range(len(wavelengths_m)), key=lambda i: abs(wavelengths_m[i] - wavelength_m), default=None)
    return best if best is not None and abs(wavelengths_m[best] - wavelength_m) <= WAVELENGTH_TOL_M else None


def plane_index(depth_m: float, depths_m) -> int | None:
    """The design plane within ``DEPTH_TOL`` (relative) of ``depth_m`` (inf matches only inf), or None."""
    for i, z in enumerate(depths_m):
        if (math.isinf(z) and math.isinf(depth_m)) or (
                math.isfinite(z) and math.isfinite(depth_m) and abs(depth_m - z) <= DEPTH_TOL * z):
            return i
    return None


def _design_problems(rec: Recordings, wavelengths_m, depths_m) -> list[str]:
    bands = ", ".join(f"{w * 1e9:g}" for w in wavelengths_m)
    planes = ", ".join("inf" if math.isinf(z) else f"{z:g}" for z in depths_m)
    out = []
    for r in rec.psf:
        where = f"{rec.path}: {r.name}"
        if r.channels == "rgb" and len(wavelengths_m) != 3:
            out.append(f"{where} channels = \"rgb\": one PSF per colour channel needs a 3-band design, this design has "
                       f"{len(wavelengths_m)} bands ({bands} nm): record each band with a narrow-band source "
                       f"(wavelength_nm = one of them)")
        if r.wavelength_m is not None and band_index(r.wavelength_m, wavelengths_m) is None:
            out.append(f"{where} wavelength_nm = {r.wavelength_m * 1e9:g} is no band of the design (within "
                       f"{WAVELENGTH_TOL_M * 1e9:g} nm): record at one of {bands} nm")
        if plane_index(r.depth_m, depths_m) is None:
            mm = plane_index(r.depth_m / 1000, depths_m) is not None  # a distance written in millimetres
            unit = f" (depth_m is in metres: {r.depth_m / 1000:g}?)" if mm else ""
            out.append(f"{where} depth_m = {r.depth_m:g} is no plane of the design (within {DEPTH_TOL:.0%}){unit}: "
                       f"place the source at one of {planes} m")
    return out


def recording_problems(rec: Recordings, wavelengths_m, depths_m, kernel: int) -> list[str]:
    """Every problem of the recordings against a design of bands ``wavelengths_m``, planes ``depths_m`` and kernel
    ``kernel`` (pixels), each naming the file and the fix: bands and planes the design lacks, unreadable frames,
    frames of one recording (or a wall pair's two views) of different sizes, dark frames of another size, frames of
    the wrong channel count or smaller than the kernel, a saturated frame, too few photons for the kernel
    (``doefab.lab.framechecks``). Every frame is read."""
    from doefab.lab.framechecks import psf_frame_problems, wall_frame_problems

    out = _design_problems(rec, wavelengths_m, depths_m)
    for r in rec.psf:
        out += psf_frame_problems(rec, r, int(kernel))
    for w in rec.wall:
        out += wall_frame_problems(rec, w)
    return out


def check_recordings(rec: Recordings, wavelengths_m, depths_m, kernel: int) -> None:
    """Raise one DoefabError listing every :func:`recording_problems` (nothing when there is none)."""
    problems = recording_problems(rec, wavelengths_m, depths_m, kernel)
    if problems:
        raise DoefabError(f"{rec.path}: the recordings cannot be used as they are ({len(problems)} "
                          f"problem{'s' * (len(problems) > 1)}, each with its fix):\n  - "
                          + "\n  - ".join(problems))


def recordings_sha256(rec: Recordings) -> str:
    """SHA-256 of the recordings file and of every frame file's name (relative to the file's folder) and bytes, in
    the file's order: the identity of what a calibration was made from."""
    h = hashlib.sha256(rec.path.read_bytes())
    for p in rec.files():
        try:
            name = p.resolve().relative_to(rec.base).as_posix()
        except ValueError:
            name = p.resolve().as_posix()
        h.update(name.encode() + b"\0")
        with open(p, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()

"""The camera: a frozen, validated description of aperture, DOE grid, lens and sensor (SI units).

Defaults are the authors' prototype (../shared/DESIGN-NOTES.md): 8.64 mm DOE clear aperture, DOE grid
1600 × 1600 at 5.4 µm, sensor 50 mm behind the lens focused at 5 m (so f ≈ 49.5 mm), 5.4 µm sensor pitch,
fused silica.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from doefab.validate import distance_or_inf, distance_record, full_precision, metres_hint
from doefab.errors import DoefabError
from doefab.optics.materials import FUSED_SILICA, Material

__all__ = ["Camera", "PRESETS", "STOP_TOLERANCE", "BLUR_ROOM_PX", "window_reach", "require_camera"]

#: a DOE baffle and a lens entrance pupil whose diameters differ by at most this fraction are "about equal": either
#: may be the stop (the reports say so); a lens pupil narrower by more cuts the DOE (``Camera.lens_cuts_doe``)
STOP_TOLERANCE = 0.01
#: the room (sensor px) a window sized for the plain half's geometric blur leaves past it: diffraction spreads the
#: light past the geometric edge (on the 16 mm f/2.8 camera with 2.4 µm pixels of tests/pipeline/test_window_blur.py,
#: a 63 px window loses 2.1–2.7 % of the half's light where the half disc reaches its edge, 1.5–2.0 % with 2 px of
#: room, 0.4–0.6 % in focus, 486–656 nm, by wave-optics PSFs; the fractions depend on the camera)
BLUR_ROOM_PX = 2


def window_reach(kernel_size: int) -> int:
    """How far a centred window of ``kernel_size`` sensor pixels reaches from the point's image on its shorter side
    (px): its pixels lie at −K//2 … K − 1 − K//2, so (K − 1) // 2 (an even window reaches one pixel less on one
    side).

    Example: ``window_reach(63)`` is 31, ``window_reach(16)`` is 7."""
    return (int(kernel_size) - 1) // 2


def require_camera(camera, what: str = "camera") -> "Camera":
    """``camera`` itself when it is a :class:`Camera`; else one error naming what was given and how to make one.

    Example: ``require_camera(Camera.preset("hdr"))`` returns it; ``require_camera("hdr")`` names
    ``doefab.Camera.preset("hdr")``."""
    if isinstance(camera, Camera):
        return camera
    hint = (f"doefab.Camera.preset({camera!r})" if isinstance(camera, str) and camera in PRESETS
            else "doefab.Camera.preset(name) or doefab.Camera(...)")
    raise DoefabError(f"{what} must be a doefab.Camera, got {type(camera).__name__} {camera!r:.60}: make one with "
                      f"{hint}")


def _plain_numbers(cam) -> None:
    """NumPy scalars (float64, float32 with the value it rounded to, integers) given for the camera's numbers become
    Python numbers: a camera compares, hashes and prints by value. Half precision is refused
    (``validate.full_precision``)."""
    import numbers

    for f in dataclasses.fields(cam):
        v = getattr(cam, f.name)
        if isinstance(v, numbers.Real) and type(v) not in (bool, int, float) and hasattr(v, "dtype"):
            full_precision(f"Camera.{f.name}", v)
            object.__setattr__(cam, f.name, int(v) if isinstance(v, numbers.Integral) else float(v))


@dataclass(frozen=True)
class Camera:
    """Split-aperture camera geometry. All lengths in metres.

    Attributes:
        aperture_diameter: clear aperture of the DOE / lens stop, metres (8.64e-3).
        doe_pitch: DOE pixel pitch, metres (5.4e-6).
        doe_pixels: DOE grid size N (the height map is N × N), pixels (1600).
        sensor_pitch: sensor pixel pitch, metres (5.4e-6).
        sensor_distance: lens (aperture plane) to sensor distance s, metres (50e-3).
        focus_distance: object distance imaged sharply on the sensor, metres; ``inf`` means s = f (5.0).
        material: DOE substrate (fused silica; others: ``doefab.material_by_name``).
        design_wavelength: wavelength whose 2π height sets the etch depths (one level = h_2π / L), metres (550e-9).
        lens_f_number: the lens's own f-number wide open (1.8, the EF 50 mm f/1.8 STM); its entrance pupil is
            focal_length / lens_f_number across. It decides which element is the aperture stop
            (:attr:`doe_is_stop`).

    Example:
        The prototype's 8.64 mm DOE on a coarser grid (256 pixels of 33.75 µm), for a quick computation:

        >>> import doefab
        >>> cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)
        >>> round(cam.aperture_diameter * 1e3, 2), cam.doe_is_stop
        (8.64, True)
    """

    aperture_diameter: float = 8.64e-3
    doe_pitch: float = 5.4e-6
    doe_pixels: int = 1600
    sensor_pitch: float = 5.4e-6
    sensor_distance: float = 50e-3
    focus_distance: float = 5.0
    material: Material = field(default=FUSED_SILICA)
    design_wavelength: float = 550e-9
    lens_f_number: float = 1.8

    def __post_init__(self) -> None:
        _plain_numbers(self)
        record_number({"lens_f_number": self.lens_f_number}, "lens_f_number", 0.5, 64.0, "", where="Camera")
        for name in ("aperture_diameter", "doe_pitch", "sensor_pitch", "sensor_distance", "design_wavelength"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise DoefabError(f"Camera.{name} must be a positive finite length in metres, got {v!r}")
            record_number({name: v}, name, *SANE_RANGES[name], where="Camera")
        fd = self.focus_distance
        if isinstance(fd, bool) or not isinstance(fd, (int, float)) or math.isnan(fd) or fd <= 0:
            raise DoefabError(f"Camera.focus_distance must be > 0 m (or inf), got {fd!r}")
        if math.isfinite(fd) and not 1e-3 <= fd <= 1e6:
            raise DoefabError(f"Camera.focus_distance = {fd!r} m is outside 1 mm – 1000 km: lengths are in metres "
                              f"(write inf to focus at infinity)")
        if not isinstance(self.doe_pixels, int) or isinstance(self.doe_pixels, bool) or not 2 <= self.doe_pixels <= 65536:
            raise DoefabError(f"Camera.doe_pixels must be an integer in 2..65536, got {self.doe_pixels!r}")
        if not isinstance(self.material, Material):
            raise DoefabError(f"Camera.material must be a doefab.Material, got {self.material!r}")
        extent = self.doe_pixels * self.doe_pitch
        if extent < self.aperture_diameter * (1 - 1e-9):
            raise DoefabError(
                f"DOE grid {self.doe_pixels} px × {self.doe_pitch:g} m = {extent:g} m is smaller than the "
                f"aperture diameter {self.aperture_diameter:g} m: raise doe_pixels to at least "
                f"{math.ceil(self.aperture_diameter / self.doe_pitch - 1e-9)} or the pitch")

    # ---- derived quantities -------------------------------------------------------------------
    @property
    def focal_length(self) -> float:
        """Thin-lens focal length f (metres) from 1/f = 1/s + 1/z_focus."""
        inv = 1.0 / self.sensor_distance + (0.0 if math.isinf(self.focus_distance) else 1.0 / self.focus_distance)
        return 1.0 / inv

    @property
    def f_number(self) -> float:
        """Working f-number s / D (dimensionless)."""
        return self.sensor_distance / self.aperture_diameter

    @property
    def lens_pupil_diameter(self) -> float:
        """Diameter of the lens's own entrance pupil wide open, focal_length / lens_f_number (metres)."""
        return self.focal_length / self.lens_f_number

    @property
    def doe_is_stop(self) -> bool:
        """True when the DOE's chrome baffle is narrower than the lens's entrance pupil; the baffle is then the
        aperture stop, the exit pupil is the lens's image of the DOE and the dual-pixel split is conjugate to
        the DOE itself, so an axial gap between DOE and lens moves nothing (the paper's prototype: 8.64 mm against
        27.5 mm)."""
        return self.aperture_diameter <= self.lens_pupil_diameter

    @property
    def lens_cuts_doe(self) -> bool:
        """True when the lens's entrance pupil is narrower than the DOE's baffle by more than ``STOP_TOLERANCE``:
        the lens then blocks the DOE's outer ring and splits the aperture at its own stop, while the PSFs are
        computed over the whole baffle, split at the DOE. Scenes (``pipeline.sampling.stop_checks``) and
        ``PSFPlan`` (unless ``check=False``) refuse such a camera; the about-equal case is modelled (the DOE's
        diffraction over the gap to the lens is propagated).

        Example: ``Camera(lens_f_number=8.0).lens_cuts_doe`` is True (a 6.2 mm pupil against the 8.64 mm DOE)."""
        return self.lens_pupil_diameter < self.aperture_diameter * (1 - STOP_TOLERANCE)

    def alias_free_px(self, lam: float) -> float:
        """Half-width of the alias-free field the DOE's sampling leaves at wavelength ``lam`` (metres), in sensor
        pixels: λ·s / (2·DOE pitch) / sensor pitch; a window of k px fits where k/2 + 0.5 does not exceed it.

        Example: ``Camera().alias_free_px(550e-9)`` is the half-field at 550 nm."""
        return lam * self.sensor_distance / (2 * self.doe_pitch) / self.sensor_pitch

    def defocus_blur_px(self, depth: float) -> float:
        """Diameter of the geometric blur of a point at ``depth`` metres (``inf``: a plane wave), in sensor pixels:
        ``D·s·|1/z_focus − 1/z| / pitch``, with D the DOE aperture (thin lens, the DOE at the aperture, as the PSFs
        are computed). Each half of the split aperture blurs the point into a half disc of this diameter, its
        straight edge through the point's image, so its light reaches half of it from the image on every side.

        Example: ``Camera(focus_distance=5.0).defocus_blur_px(float("inf"))`` is the blur of a star when focused
        at 5 m."""
        inv_z = 0.0 if math.isinf(depth) else 1.0 / depth
        inv_f = 0.0 if math.isinf(self.focus_distance) else 1.0 / self.focus_distance
        return self.aperture_diameter * self.sensor_distance * abs(inv_f - inv_z) / self.sensor_pitch

    def widest_blur(self, depths) -> tuple[float, float]:
        """(plane in metres, the plain half's geometric blur radius there in sensor px) at the plane among
        ``depths`` (metres) of the largest blur: ``defocus_blur_px`` / 2, how far the half disc reaches from the
        point's image.

        Example: ``Camera().widest_blur([float("inf"), 1.0])`` is 1 m and 32 px (to rounding): at 1 m the 8.64 mm
        aperture, focused at 5 m, blurs a point into a half disc of 32 px radius."""
        return max(((float(z), self.defocus_blur_px(z) / 2) for z in depths), key=lambda zr: zr[1])

    def window_holds_blur(self, depths, kernel_size: int) -> bool:
        """True where a centred window of ``kernel_size`` sensor pixels reaches the plain half's geometric blur at
        every plane among ``depths`` (metres): its radius (``widest_blur``) is at most ``window_reach(kernel_size)``.
        Light beyond the window is missing from the PSFs; ``BLUR_ROOM_PX`` more leaves room for diffraction.

        Example: ``Camera().window_holds_blur([1.0], 63)`` is False (32 px of blur, 31 px of window); with
        ``kernel_size`` 67 it is True."""
        return self.widest_blur(depths)[1] <= window_reach(kernel_size) + 1e-9  # a blur of exactly the reach fits

    def window_for_blur(self, depths) -> int:
        """The smallest odd window (sensor px) that holds the plain half's blur at every plane among ``depths``
        (metres) with ``BLUR_ROOM_PX`` of room past its edge: 2·⌈radius + room⌉ + 1.

        Example: ``Camera().window_for_blur([1.0])`` is 69 (a 32 px radius, 2 px of room)."""
        return 2 * math.ceil(self.widest_blur(depths)[1] + BLUR_ROOM_PX - 1e-9) + 1

    def replace(self, **changes) -> "Camera":
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def preset(cls, name: str, **overrides) -> "Camera":
        """Camera of a task preset: ``"default"``, ``"hdr"``, ``"hyperspectral"`` or ``"depth"``."""
        try:
            base = PRESETS[name]
        except KeyError:
            raise DoefabError(f"unknown camera preset {name!r}: choose one of {sorted(PRESETS)}") from None
        return cls(**{**base, **overrides})

    def to_dict(self) -> dict:
        """JSON-ready dict; every length in metres (keys carry ``_m`` where a unit applies)."""
        return {
            "aperture_diameter_m": self.aperture_diameter,
            "doe_pitch_m": self.doe_pitch,
            "doe_pixels": self.doe_pixels,
            "sensor_pitch_m": self.sensor_pitch,
            "sensor_distance_m": self.sensor_distance,
            "focus_distance_m": distance_record(self.focus_distance),
            "design_wavelength_m": self.design_wavelength,
            "focal_length_m": self.focal_length,
            "lens_f_number": self.lens_f_number,
            "material": self.material.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict, where: str = "camera record") -> "Camera":
        """A camera from :meth:`to_dict`'s record (e.g. read from design.json), every field checked for type,
        finiteness and a plausible range in its unit; the error names the field, the file and the fix."""
        if not isinstance(d, dict):
            raise DoefabError(f"{where}: the camera must be a JSON object of Camera.to_dict() fields")
        missing = [k for k in RECORD_RANGES if k not in d] + [k for k in ("focus_distance_m", "material") if k not in d]
        if missing:
            raise DoefabError(f"{where}: camera lacks {missing}; expected Camera.to_dict() fields")
        vals = {k: record_number(d, k, lo, hi, unit, where, integer=(k == "doe_pixels"))
                for k, (lo, hi, unit) in RECORD_RANGES.items()}
        fd = d["focus_distance_m"]
        inf = distance_or_inf(fd) == math.inf
        focus = math.inf if inf else record_number(d, "focus_distance_m", 1e-3, 1e6, "m", where)
        material = Material.from_dict(d["material"], where=f"{where}: material")
        n = float(material.index(vals["design_wavelength_m"]))
        if not 1.0 < n < 4.0:
            raise DoefabError(f"{where}: material {material.name!r} has index {n:g} at the design wavelength; a DOE "
                              f"substrate lies between 1 and 4: check its Sellmeier coefficients")
        lens_n = _lens_f_number(d, where)
        try:
            cam = cls(aperture_diameter=vals["aperture_diameter_m"], doe_pitch=vals["doe_pitch_m"],
                      doe_pixels=int(vals["doe_pixels"]), sensor_pitch=vals["sensor_pitch_m"],
                      sensor_distance=vals["sensor_distance_m"], focus_distance=focus,
                      design_wavelength=vals["design_wavelength_m"], material=material,
                      lens_f_number=lens_n)
        except DoefabError as exc:
            raise DoefabError(f"{where}: {exc}") from None
        fl = d.get("focal_length_m")
        if fl is not None and (not isinstance(fl, (int, float)) or abs(fl - cam.focal_length) > 1e-9 * cam.focal_length):
            raise DoefabError(f"{where}: focal_length_m {fl!r} disagrees with sensor_distance_m and focus_distance_m "
                              f"({cam.focal_length:.9g} m): the record was edited inconsistently")
        return cam


def _lens_f_number(d: dict, where: str) -> float:
    """The record's lens f-number; records written before it was kept describe the prototype's f/1.8 lens."""
    if "lens_f_number" not in d:
        return 1.8
    return record_number(d, "lens_f_number", 0.5, 64.0, "", where)


# what a Camera accepts at all (metres): wide enough for test optics and simulations, narrow enough that a
# length typed in mm, µm or nm is caught
SANE_RANGES = {
    "aperture_diameter": (1e-6, 1.0, "m"),
    "doe_pitch": (1e-8, 1e-2, "m"),
    "sensor_pitch": (1e-8, 1e-2, "m"),
    "sensor_distance": (1e-4, 10.0, "m"),
    "design_wavelength": (100e-9, 20e-6, "m"),
}

# plausible ranges of a camera record's fields (lo, hi, unit); a value outside is almost always a unit slip
RECORD_RANGES = {
    "aperture_diameter_m": (1e-4, 0.2, "m"),
    "doe_pitch_m": (1e-7, 1e-3, "m"),
    "doe_pixels": (2, 20000, "pixels"),
    "sensor_pitch_m": (3e-7, 1e-4, "m"),
    "sensor_distance_m": (1e-3, 2.0, "m"),
    "design_wavelength_m": (200e-9, 2e-6, "m"),
}


def record_number(d: dict, key: str, lo: float, hi: float, unit: str, where: str, integer: bool = False) -> float:
    """``d[key]`` as a finite number within [lo, hi] (unit ``unit``), or one clear error naming the field."""
    v = d.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not float(v).is_integer()):
        kind = "an integer" if integer else "a number"
        raise DoefabError(f"{where}: {key} must be {kind} ({unit}), got {v!r}")
    if not math.isfinite(v) or not lo <= v <= hi:
        hint = metres_hint(v, lo, hi) if unit == "m" and math.isfinite(v) else ""
        hint = f" — lengths here are in metres{hint}" if hint else ""
        raise DoefabError(f"{where}: {key} = {v!r} is outside {lo:g}–{hi:g} {unit}{hint}")
    return float(v)


#: Camera presets by name, as the fields each changes from :class:`Camera`'s defaults (lengths in metres):
#: ``"default"`` (the prototype: 1600² DOE pixels at 5.4 µm), ``"hdr"`` (3200² at 2.7 µm),
#: ``"hyperspectral"`` (1600² at 5.4 µm) and ``"depth"`` (1600² at 5.4 µm, focused at 3.5 m).
PRESETS: dict[str, dict] = {
    "default": {},
    # Authors' released configurations (DESIGN-NOTES): HDR uses a finer DOE grid.
    "hdr": {"doe_pixels": 3200, "doe_pitch": 2.7e-6},
    "hyperspectral": {"doe_pixels": 1600, "doe_pitch": 5.4e-6},
    "depth": {"doe_pixels": 1600, "doe_pitch": 5.4e-6, "focus_distance": 3.5},
}

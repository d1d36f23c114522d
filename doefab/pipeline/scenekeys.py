"""Every key a scene file takes, in one table: its type, unit, range, default and meaning.

The same table validates scene files (``scene.load_scene``), writes the commented template of ``doefab scene
new`` and is the scene-key reference of the documentation. Units are in the key names (``_mm``, ``_um``,
``_nm``, ``_m``, ``_px``); a value far outside a key's range is almost always another unit.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable, NamedTuple

from doefab.applications import APPLICATIONS, has
from doefab.errors import DoefabError
from doefab._devices import DEVICE_WORDS, device_syntax
from doefab.fabrication.process import DEFAULT_LEVELS, LEVEL_CHOICES
from doefab.imaging.sensor import DEFAULT_FULL_WELL_E, DEFAULT_READ_NOISE_E, FULL_WELL_RANGE_E, READ_NOISE_RANGE_E
from doefab.optics.camera import PRESETS
from doefab.optics.materials import SUBSTRATES, substrate_name
from doefab.tolerance.schedulers import MAX_WORKERS, parse_scheduler

__all__ = ["Key", "KEYS", "HOW_NOT_WHAT", "RENAMED", "STAGES", "keys_of", "item_text", "values_text", "template",
           "key_table_markdown", "toml_value", "WeightsMode", "WEIGHTS_MODES", "weights_mode"]

STAGES = ("design", "masks", "holder", "reconstruction", "tolerance", "report")


class WeightsMode(NamedTuple):
    """Which networks a scene's reconstruction stage evaluates (the ``reconstruction.weights`` key), one row each.
    name: the key's value.  trains: networks are trained here for the scene's system (in the stage's
    ``weights`` folder).  any_system: the stage runs on a new design or another sensor (False: it is skipped
    there; the shipped networks fit only the committed design and the default sensor).  flagged: the networks
    were not trained for the captures they see; the report says so with a warning.  help: one line."""

    name: str
    trains: bool
    any_system: bool
    flagged: bool
    help: str


WEIGHTS_MODES = {m.name: m for m in (
    WeightsMode("shipped", False, False, False, "the shipped networks (the committed designs')"),
    WeightsMode("train", True, True, False, "networks trained for this design"),
    WeightsMode("shipped-anyway", False, True, True, "the shipped ones given this design's PSF (with a warning)"))}


DEFAULT_WEIGHTS = "shipped"


def weights_mode(name: str | None) -> WeightsMode:
    """The ``WEIGHTS_MODES`` row of ``name`` (None: the key's default, ``DEFAULT_WEIGHTS``).

    Example::

        >>> weights_mode("train").trains
        True
    """
    return WEIGHTS_MODES[DEFAULT_WEIGHTS if name is None else name]


@dataclass(frozen=True)
class Key:
    """One scene key: its section ("" for top-level keys), name, kind (float, int, str, bool, list, choice),
    unit (as in its name: mm, µm, nm, m, px), allowed range [lo, hi] in that unit, choices, default and meaning.

    A list key's ``item`` is the kind of each of its items ("float": within [lo, hi], or inf with ``inf``;
    "choice": one of ``choices``); each item may appear once. A choice or str key with a
    ``resolve`` takes whatever that resolver accepts (it returns the choice meant, or raises a DoefabError)."""

    section: str  # "" for top-level keys
    name: str
    kind: str  # float, int, str, bool, list, choice
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    choices: tuple = ()
    default: str = ""
    help: str = ""
    item: str = ""
    resolve: Callable | None = None
    inf: bool = False  # a float key (or a list key's float items) that also takes inf (TOML's inf, or "inf")
    only: str = ""  # the application property (``applications.PROPERTIES``) a scene needs for this key, or ""


def _knots(n: int) -> int:
    """``design.knots``: 0 or at least 2 (one knot makes no profile)."""
    if n == 1:
        raise DoefabError("1 knot makes no profile: give 0 (one per design-grid pixel along the radius) or at least 2")
    return n


KEYS = (
    Key("", "task", "choice", choices=tuple(APPLICATIONS), default="required",
        help="what the camera adds: HDR (streak DOE), 31-band spectra (grating), depth (half-ring)"),
    Key("", "stages", "list", choices=STAGES, item="choice", default="all",
        help="stages to run (always in this order): design, masks, holder, reconstruction, tolerance, report"),
    Key("", "device", "choice", choices=DEVICE_WORDS, resolve=partial(device_syntax, name="scene"), default="auto",
        help="where torch computes (design, networks, tolerance): auto (a CUDA GPU when torch sees one, else the "
             "CPU), cpu, cuda or cuda:N (GPU N); doefab run --device overrides it"),
    Key("camera", "preset", "choice", choices=tuple(PRESETS), default="the task's",
        help="the paper's prototype (Canon EF 50 mm f/1.8, 8.64 mm DOE, 5.4 µm pixels) to start from; the keys "
             "below replace its values"),
    Key("camera", "focal_length_mm", "float", "mm", 1.0, 2000.0, default="49.5 (prototype)",
        help="the lens's focal length; the sensor distance follows from it and the focus distance"),
    Key("camera", "sensor_distance_mm", "float", "mm", 1.0, 2000.0, default="from focal_length_mm",
        help="lens to sensor, instead of focal_length_mm"),
    Key("camera", "aperture_diameter_mm", "float", "mm", 0.1, 200.0, default="8.64 (prototype)",
        help="the DOE's clear aperture (its chrome baffle)"),
    Key("camera", "f_number", "float", "", 0.5, 64.0, default="from aperture_diameter_mm",
        help="focal length / DOE aperture, instead of aperture_diameter_mm"),
    Key("camera", "lens_f_number", "float", "", 0.5, 64.0, default="1.8 (prototype)",
        help="the lens's own f-number wide open: its entrance pupil must not be narrower than the DOE's "
             "baffle, which is then the aperture stop"),
    Key("camera", "focus_distance_m", "float", "m", 1e-3, 1e6, default="5 (3.5 for depth)", inf=True,
        help="object distance imaged sharply; inf focuses at infinity (the sensor one focal length behind the lens)"),
    Key("camera", "sensor_pitch_um", "float", "µm", 0.3, 100.0, default="5.4 (prototype)",
        help="sensor pixel pitch"),
    Key("camera", "sensor_diagonal_mm", "float", "mm", 1.0, 200.0, default="none: the holder's 24°",
        help="the sensor's diagonal (43.3 for full frame): the holder's hole in front of the DOE flares to pass "
             "the field it sees, atan(diagonal / 2 / sensor distance), unless holder.field_half_angle_deg is given; "
             "a sensor smaller than the PSF window or the test images is warned of"),
    Key("camera", "doe_pitch_um", "float", "µm", 0.1, 1000.0, default="5.4 (2.7 for HDR)",
        help="the fab's DOE pixel; the DOE grid is the aperture divided by it"),
    Key("camera", "split", "choice", choices=("vertical", "horizontal"), default="vertical",
        help="the dual-pixel split line on the sensor; the optics are computed in the DOE's frame, and for "
             "horizontal the holder stage says to mount the die turned by 90°"),
    Key("camera", "sensor_distance_m", "float", "m", 1e-3, 2.0, default="from the preset",
        help="lens to sensor in metres (the same as sensor_distance_mm)"),
    Key("sensor", "response", "str", default="Canon EOS 5D Mark II",
        help="the sensor's RGB spectral sensitivities (they form the hyperspectral task's captures): "
             "\"Canon EOS 5D Mark II\", \"Nikon D5100\", \"Sigma SD Merrill\" (400–680 nm), or a CSV path (relative "
             "to the scene) with a header line and rows wavelength_nm, R, G, B"),
    Key("sensor", "full_well_e", "float", "e⁻", *FULL_WELL_RANGE_E, default=f"{DEFAULT_FULL_WELL_E:g}",
        help="electrons at a capture value of 1 (one dual-pixel photodiode's full well at the ISO used)"),
    Key("sensor", "read_noise_e", "float", "e⁻", *READ_NOISE_RANGE_E, default=f"{DEFAULT_READ_NOISE_E:g}",
        help="read noise, rms electrons (at the ISO used)"),
    Key("optics", "wavelengths_nm", "list", "nm", 300.0, 1100.0, item="float", default="the task's",
        help="bands to design and reconstruct for (RGB 656/589/486; spectra 400–700 every 10); HDR and depth "
             "networks take three, longest first, one per colour channel (R, G, B)"),
    Key("optics", "depths_m", "list", "m", 1e-3, 1e6, inf=True, item="float", default="the task's",
        help="depth planes (depth: 1–5 m every 0.25; others: the focus distance); inf for a plane wave"),
    Key("optics", "kernel_px", "int", "px", 15, 1023, default="95, 191, 63",
        help="PSF window in sensor pixels"),
    Key("design", "optimizer", "choice", choices=("adam", "lbfgs", "mma"), default="the committed design's",
        help="optimiser; lbfgs and mma (nlopt) take a pixel design of limited size: doctor names the design grid "
             "they take"),
    Key("design", "iterations", "int", "steps", 1, 100000, default="the committed design's", help="optimiser steps"),
    Key("design", "sampling", "int", "DOE px", 1, 16, default="the committed design's",
        help="DOE pixels per design pixel (2: a half grid, 4× faster)"),
    Key("design", "seed", "int", "", 0, 2**32 - 1, default="0", help="random seed"),
    Key("design", "parameterization", "choice", choices=("pixel", "radial"), default="the committed design's",
        help="free pixels, or a rotationally symmetric profile"),
    Key("design", "knots", "int", "", 0, 100000, default="0", resolve=_knots,
        help="radial knots (0: one per design-grid pixel along the radius; else at least 2); parameterization "
             "radial only"),
    Key("design", "ring_law", "choice", choices=("seed", "defocus"), default="the committed design's",
        only="depth",
        help="depth: ring radius linear in depth (the paper's law, \"seed\") or in inverse depth (defocus)"),
    Key("design", "ring_max_px", "float", "px", 0.0, 2047.0, default="the camera's defocus blur",
        only="depth",
        help="depth: ring radius at the nearest plane"),
    Key("design", "ring_width_px", "float", "px", 0.01, 100.0, default="1",
        only="depth",
        help="depth: half-width of the ring the target and metric count (sensor pixels either side of the arc)"),
    Key("design", "streak_arm_px", "int", "px", 1, 2047, default="40", only="highlights",
        help="HDR: length of the streak's arms"),
    Key("design", "streak_band_px", "int", "px", 0, 64, default="1",
        only="highlights",
        help="HDR: half-width of the band around the arms the metric counts"),
    Key("design", "grating_period_um", "float", "µm", 0.5, 1e4, default="16 DOE pixels",
        only="spectral",
        help="spectra: grating period"),
    Key("design", "grating_box_px", "int", "px", 0, 64, default="1",
        only="spectral",
        help="spectra: half-width of each band's metric box at its first order"),
    Key("fabrication", "n_levels", "choice", choices=LEVEL_CHOICES, default=str(DEFAULT_LEVELS),
        help="the number of etch levels L: log2 L binary masks"),
    Key("fabrication", "material", "choice", choices=tuple(SUBSTRATES), resolve=substrate_name,
        default="fused silica", help="DOE substrate (the name in any case)"),
    Key("fabrication", "design_wavelength_nm", "float", "nm", 200.0, 2000.0, default="550",
        help="the wavelength whose 2π height sets the etch depths"),
    Key("fabrication", "min_feature_um", "float", "µm", 0.01, 1000.0, default="none",
        help="the fab's smallest feature; the DOE pitch must not be smaller"),
    Key("fabrication", "pattern_faces", "choice", choices=("lens", "scene"), default="lens",
        help="which way the patterned face is mounted (the layout is mirrored for lens)"),
    Key("fabrication", "oasis", "bool", default="false", help="also write OASIS"),
    Key("reconstruction", "weights", "choice", choices=tuple(WEIGHTS_MODES), default=DEFAULT_WEIGHTS,
        help="; ".join(f"{m.name}: {m.help}" for m in WEIGHTS_MODES.values())),
    Key("reconstruction", "minutes", "float", "min", 0.05, 600.0, default="6",
        help="training time per network (weights = train)"),
    Key("reconstruction", "images", "int", "scenes", 1, 10000, default="4", help="held-out test scenes"),
    Key("reconstruction", "size_px", "int", "px", 64, 2048, default="256", help="test image side (a multiple of 32)"),
    Key("tolerance", "budget", "str", default="default", help="\"default\" or a budget TOML path"),
    Key("tolerance", "samples", "int", "parts", 0, 100000, default="20", help="Monte Carlo parts"),
    Key("tolerance", "supersample", "int", "", 1, 8, default="the grid study's choice",
        help="fix the simulation grid (cells per DOE pixel)"),
    Key("tolerance", "workers", "int", "processes", 1, MAX_WORKERS, default="auto",
        help="local worker processes judging the Monte Carlo's parts (auto: one per core when there are at least 4 "
             "parts per core, no more than fit in memory); how the parts run, not what they give: a change reruns "
             "nothing"),
    Key("tolerance", "scheduler", "str", default="none", resolve=parse_scheduler,
        help="a Dask scheduler judging the Monte Carlo's parts instead of local workers: local:N (a LocalCluster of "
             "N workers started for the run) or tcp://HOST:PORT (a running scheduler, which must answer when the "
             "run starts); a change reruns nothing"),
)


# keys of a section that say how a stage runs, not what it computes: a change to them reruns nothing
HOW_NOT_WHAT = {"tolerance": ("workers", "scheduler")}


# keys a scene file may still hold under an earlier name: (section, old name) -> the name to write instead
RENAMED = {("fabrication", "levels"): "n_levels"}


def keys_of(section: str) -> dict:
    """The keys of one section (``"camera"``, ``"fabrication"``…; ``""`` for the top level), by name."""
    return {k.name: k for k in KEYS if k.section == section}


def _range(k: Key) -> str:
    """``lo–hi`` in the key's unit (or "no unit"), integers written in full."""
    lo, hi = (f"{int(k.lo)}", f"{int(k.hi)}") if k.kind == "int" else (f"{k.lo:g}", f"{k.hi:g}")
    return f"{k.unit or 'no unit'}, {lo}–{hi}"


def item_text(k: Key) -> str:
    """What each item of a list key takes: one of its choices, or a number in its range (or inf)."""
    if k.item == "choice":
        return "one of " + ", ".join(map(str, k.choices))
    return f"within {k.lo:g}–{k.hi:g} {k.unit}" + (" or inf" if k.inf else "")


def values_text(k: Key) -> str:
    """What a key takes, as the key table and the template print it: its unit (or "no unit") and range, its
    choices, or for a list what each item takes."""
    if k.kind == "list":
        return f"a list, each item {item_text(k)}, none twice"
    if k.choices:
        return ", ".join(map(str, k.choices)) + (" (any case)" if k.resolve else "")
    if k.lo is not None:
        return _range(k) + (", or inf" if k.inf else "")
    return {"bool": "true or false", "str": "text, no unit"}[k.kind]


def key_table_markdown() -> str:
    """The scene-key reference (one row per key)."""
    rows = ["| key | unit and range, or values | default | meaning |", "| --- | --- | --- | --- |"]
    for k in KEYS:
        name = f"{k.section}.{k.name}" if k.section else k.name
        rows.append(f"| `{name}` | {values_text(k)} | {k.default} | {k.help} |")
    rows.append("| `holder.*` | any `doefab holder --set` parameter (mm) | the holder's defaults | the lens's thread "
                "or barrel and the part |")
    return "\n".join(rows)


_EXAMPLES = {
    "hdr": {"optics": {"wavelengths_nm": [656, 589, 486]}, "design": {"iterations": 60, "sampling": 2}},
    "hyperspectral": {"optics": {"wavelengths_nm": list(range(400, 701, 10))},
                      "design": {"iterations": 300, "grating_period_um": 96.0}},  # first order ≤ 68 px at 700 nm
    # the window holds the plain half's blur at 1 m when sharp at 5 m (32.9 px on this camera), so the ring follows it
    "depth": {"optics": {"depths_m": [1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0], "kernel_px": 73},
              "design": {"iterations": 600, "sampling": 2, "parameterization": "radial", "ring_law": "defocus"}},
}


def template(task: str) -> str:
    """A commented scene file for ``task`` with every key, its unit and range (values: a 35 mm f/4 camera)."""
    ex = _EXAMPLES[task]
    values = {("camera", "focal_length_mm"): 35.0, ("camera", "f_number"): 4.0, ("camera", "lens_f_number"): 2.0,
              ("camera", "focus_distance_m"): 3.5 if has(task, "depth") else 5.0, ("camera", "sensor_pitch_um"): 3.76,
              ("camera", "sensor_diagonal_mm"): 28.2, ("camera", "doe_pitch_um"): 4.0, ("fabrication", "n_levels"): 16,
              ("fabrication", "material"): "fused silica", ("fabrication", "min_feature_um"): 2.0,
              ("reconstruction", "weights"): "train", ("reconstruction", "minutes"): 6.0,
              ("tolerance", "samples"): 12, ("tolerance", "budget"): "default"}
    for sec, d in ex.items():
        values.update({(sec, k): v for k, v in d.items()})
    values.update({("", "task"): task, ("", "stages"): list(STAGES)})
    lines = ["# doefab scene (doefab scene new). Every key with its unit and range; commented keys keep their "
             "default."]
    section = ""
    for k in KEYS:
        if k.name in ("preset", "sensor_distance_m") or (k.only and not has(task, k.only)):
            continue  # (a key of another task's scenes is refused in this one)
        if k.section != section:
            section = k.section
            lines += ["", f"[{section}]"]
        note = f"# {k.help} ({values_text(k)}; default {k.default})"
        if (k.section, k.name) in values:
            lines += [note, f"{k.name} = {toml_value(values[(k.section, k.name)])}"]
        else:
            lines += [note, f"# {k.name} = "]
    lines += ["", "[holder]", "# the lens's filter thread (mm); any `doefab holder --set` parameter",
              "thread_diameter_mm = 49.0"]
    return "\n".join(lines) + "\n"


def toml_value(v) -> str:
    """A value as a scene file writes it (a string quoted, a list in brackets)."""
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v) if not isinstance(v, list) else "[" + ", ".join(map(toml_value, v)) + "]"

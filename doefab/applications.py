"""The applications doefab designs for, one row each (``APPLICATIONS``): every layer looks an application up here
rather than keeping its own table or comparing its name as a string.

An application is what the user asks for in a scene file (``task = "hdr"``): the design task whose DOE serves it
(``design_task``: streak, grating, half-ring), and the metric a reconstructed scene is judged by first
(``primary_metric``, its unit and direction) — the one the tolerance study's delivered yield, the reports'
"what limits it" and the proposed-against-ablation comparisons rank by.

Example::

    >>> from doefab.applications import application, of_design
    >>> application("hdr").design_task
    'streak'
    >>> of_design("half-ring").name
    'depth'
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Callable, NamedTuple

from doefab.errors import DoefabError

__all__ = ["Application", "Metric", "APPLICATIONS", "application", "of_design", "has", "design_is", "NAMES",
           "DESIGN_TASKS", "PROPERTIES", "HDR_PEAK", "View", "band_problem"]

HDR_PEAK = 256.0  # the paper's Table 1: HDR PSNR with a maximum value of 2^8 (radiance; 1 is the plain capture's clip)


class Metric(NamedTuple):
    """A metric an application's reconstructions are scored by. name: the key its metric function returns.
    label: how reports name it.  unit: as printed ("dB", "m", "rad"; "" for a ratio or for HDR radiance, which is
    relative).  higher_is_better: its direction.  span: (lo, hi) the values it can take, in ``unit`` (the range
    of a tolerance budget's absolute limit on it).  scale: what a unitless value is relative to, where it is
    not a plain ratio (records write it beside the unit).  scale_unit: how a report prints that scale after a
    value ("× clip"), where ``unit`` is "" (spec keys spell the unit, which stays empty for a relative one)."""

    name: str
    label: str
    unit: str
    higher_is_better: bool
    span: tuple[float, float]
    scale: str = ""
    scale_unit: str = ""

    @property
    def shown_unit(self) -> str:
        """The unit a report prints beside a value: ``unit``, else ``scale_unit`` ("" for a plain ratio)."""
        return self.unit or self.scale_unit


@dataclass(frozen=True)
class Application:
    """name: the scene file's ``task``.  design_task: the DOE design task that serves it.  primary_metric: the
    reconstruction metric it is judged by first, in ``primary_unit`` ("dB", "m"); ``higher_is_better`` its
    direction.  summary: one line for help texts.  What its scenes are, which every layer asks instead of the
    name: ``spectral`` — spectra on the design's bands, seen through the sensor's RGB response (its sensor
    record holds the response); ``depth`` — the network estimates metres, the scenes span depths between the
    design's planes (a PSF per plane); ``highlights`` — the scenes clip and the network's solve reads both halves'
    PSFs.  camera_preset: the ``doefab.optics.camera.PRESETS`` row its scenes start from (the authors' camera
    for it).  network: the module of its reconstruction network, which has ``default_arch(variant)``,
    ``build(variant, arch)`` and ``loss(pred, target)`` (imported only when a network is built).

    Reconstruction: ``metrics`` the ``Metric`` rows its scenes are scored by, in the order budgets and reports
    list them, computed by ``metric_function`` ("module:function" of (pred, target) → {name: value}, imported
    when called); ``kernel`` the smallest PSF window (sensor pixels) its captures are simulated with;
    ``out_channels`` the network's outputs; ``train_metric`` the validation metric logged while training;
    ``crop`` the training crops' side (pixels); ``image_unit`` and ``error_unit`` what an evaluation figure's
    result and error panels show; ``scene_function`` ("module:function" of (split, index, rng, side px, PSF
    pair) → (scene [C, side, side], depth target in metres or None, per-plane masks or None, where the target
    was measured or None)) makes its scenes (``reconstruction.specs.render_scene`` renders them)."""

    name: str
    design_task: str
    primary_metric: str
    primary_unit: str
    higher_is_better: bool
    summary: str
    camera_preset: str = "default"
    network: str = ""
    spectral: bool = False
    depth: bool = False
    highlights: bool = False
    metrics: tuple[Metric, ...] = ()
    metric_function: str = ""
    kernel: int = 95
    out_channels: int = 3
    train_metric: str = "psnr"
    crop: int = 96
    image_unit: str = ""
    error_unit: str = ""
    scene_function: str = ""

    def metric(self, name: str) -> Metric:
        """The ``Metric`` row called ``name``; a DoefabError naming this application's metrics for any other."""
        got = next((m for m in self.metrics if m.name == name), None)
        if got is None:
            raise DoefabError(f"{self.name} has no metric {name!r}: choose one of "
                              f"{', '.join(m.name for m in self.metrics)}")
        return got

    def function(self, field: str):
        """The function a "module:function" row of this application names (``metric_function``,
        ``scene_function``), its module imported now (heavy ones stay out of ``import doefab``)."""
        import importlib

        module, name = getattr(self, field).split(":")
        return getattr(importlib.import_module(module), name)


_PSNR = (0.0, 100.0)  # dB
_CLIP = "radiance in units of the plain capture's clipping level"
APPLICATIONS = {a.name: a for a in (
    Application("hdr", "streak", "psnr_highlight", "dB", True,
                "high dynamic range from one exposure: a streak PSF spreads clipped highlights", camera_preset="hdr",
                network="doefab.reconstruction.hdrnet", highlights=True,
                metrics=(Metric("psnr_highlight", "highlight PSNR", "dB", True, _PSNR),
                         Metric("psnr", "PSNR", "dB", True, _PSNR),
                         Metric("rmse_highlight", "highlight RMSE", "", False, (0.0, HDR_PEAK), _CLIP, "× clip"),
                         Metric("rmse", "RMSE", "", False, (0.0, HDR_PEAK), _CLIP, "× clip")),
                metric_function="doefab.reconstruction.metrics:hdr_metrics", kernel=95, out_channels=3,
                image_unit="log(1 + radiance) / log(257)", error_unit="radiance",
                scene_function="doefab.reconstruction.specs:hdr_scene"),
    Application("hyperspectral", "grating", "psnr", "dB", True,
                "31 spectral bands from an RGB sensor: a grating PSF disperses the coded half",
                camera_preset="hyperspectral", network="doefab.reconstruction.spectralnet", spectral=True,
                metrics=(Metric("psnr", "PSNR", "dB", True, _PSNR),
                         Metric("sam", "spectral angle (SAM)", "rad", False, (0.0, math.pi)),
                         Metric("ssim", "SSIM", "", True, (-1.0, 1.0))),
                metric_function="doefab.reconstruction.metrics:spectral_metrics", kernel=191, out_channels=31,
                image_unit="band-mean radiance", error_unit="radiance",
                scene_function="doefab.reconstruction.specs:spectral_scene"),
    Application("depth", "half-ring", "mae", "m", False,
                "depth from one exposure: a half-ring PSF that changes with distance",
                camera_preset="depth", network="doefab.reconstruction.depthnet", depth=True,
                metrics=(Metric("mae", "depth MAE", "m", False, (0.0, 1000.0)),
                         Metric("rmse", "depth RMSE", "m", False, (0.0, 1000.0)),
                         Metric("delta125", "pixels within 25 % of the depth (δ<1.25)", "", True, (0.0, 1.0)),
                         Metric("log10", "mean absolute log10 depth error", "", False, (0.0, 10.0))),
                metric_function="doefab.reconstruction.metrics:depth_metrics", kernel=95, out_channels=1,
                # crop 128: better than 96 on validation scenes, 160 no better (benchmarks/results/
                # depth_training_crop.md); a cost volume with a 95-pixel PSF needs room
                train_metric="mae", crop=128, image_unit="depth (m)", error_unit="m",
                scene_function="doefab.reconstruction.specs:depth_scene"),
)}
NAMES = tuple(APPLICATIONS)
DESIGN_TASKS = tuple(a.design_task for a in APPLICATIONS.values())
PROPERTIES = ("spectral", "depth", "highlights")


def application(name: str) -> Application:
    """The application called ``name``; a DoefabError naming the choices for any other.

    Example: ``application("depth").primary_metric`` → ``"mae"`` (metres, lower is better)."""
    if name not in APPLICATIONS:
        raise DoefabError(f"unknown application {name!r}: choose one of {', '.join(NAMES)}")
    return APPLICATIONS[name]


def of_design(design_task: str) -> Application | None:
    """The application a design task serves (None: a design task no application uses, e.g. a test's).

    Example: ``of_design("grating").name`` → ``"hyperspectral"``."""
    return next((a for a in APPLICATIONS.values() if a.design_task == design_task), None)


def has(name: str, what: str) -> bool:
    """Whether the application ``name`` (a scene file's ``task``) has the property ``what`` ("spectral", "depth"
    or "highlights"; ``Application``): False for a name no application has (a test's toy task).

    Example: ``has("hyperspectral", "spectral")`` → True; ``has("hdr", "depth")`` → False."""
    if what not in PROPERTIES:
        raise DoefabError(f"unknown application property {what!r}: choose one of {', '.join(PROPERTIES)}")
    return bool(name in APPLICATIONS and getattr(APPLICATIONS[name], what))


def design_is(design_task: str, what: str) -> bool:
    """Whether the application a design task serves has the property ``what`` (``has``); False for a design task
    no application uses.

    Example: ``design_is("half-ring", "depth")`` → True."""
    app = of_design(design_task)
    return has(app.name if app is not None else "", what)  # an unknown ``what`` is an error either way


def band_problem(name: str, wavelengths_m) -> str | None:
    """Why a design on ``wavelengths_m`` (metres) cannot feed application ``name``'s networks, or None when it can.
    A spectral application takes any bands (its scenes are spectra on them); the others' scenes are the camera's
    own RGB, so their networks need one PSF per colour channel: three bands, longest first (R, G, B).

    Example: ``band_problem("depth", [656e-9, 589e-9, 486e-9])`` → None; ``band_problem("depth", [1064e-9])`` →
    ``"the depth network takes the camera's RGB captures, one PSF per colour channel: it needs three bands …,
    got [1064]: design it for three such bands"``; ``band_problem("hyperspectral", [550e-9])`` → ``"… at least
    two distinct bands …"``."""
    nm = [round(float(w) * 1e9, 3) for w in wavelengths_m]
    got = ", ".join(f"{w:g}" for w in nm)
    if has(name, "spectral"):  # any bands, but a spectrum's angle (its metric) needs two or more distinct ones
        if len(set(nm)) >= 2:
            return None
        return (f"the {name} network recovers a spectrum and scores it by its angle, which needs at least two "
                f"distinct bands, got [{got}]: design it for two or more bands")
    if len(nm) == 3 and nm[0] > nm[1] > nm[2]:
        return None
    return (f"the {name} network takes the camera's RGB captures, one PSF per colour channel: it needs three bands "
            f"in nm, longest first (red, green, blue; e.g. [656, 589, 486]), got [{got}]: design it for three such "
            f"bands")


class View(Mapping):
    """A read-only table {key: ``value(row)``} over the registry, read on every lookup (a row added to or changed
    in ``APPLICATIONS`` shows at once): keyed by the application's name, or by ``key(row)`` (e.g. its design
    task). The other layers' per-application tables are such views, never copies.

    Example: ``View(lambda a: a.primary_metric)["depth"]`` → ``"mae"``;
    ``dict(View(lambda a: a.name, key=lambda a: a.design_task))["grating"]`` → ``"hyperspectral"``."""

    def __init__(self, value: Callable[[Application], object], key: Callable[[Application], str] | None = None):
        self._value, self._key = value, key or (lambda a: a.name)

    def _rows(self) -> dict:
        return {self._key(a): a for a in APPLICATIONS.values()}

    def __getitem__(self, key):
        return self._value(self._rows()[key])

    def __iter__(self):
        return iter(self._rows())

    def __len__(self) -> int:
        return len(self._rows())

    def __repr__(self) -> str:
        return f"View({dict(self)!r})"

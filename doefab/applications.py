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

from dataclasses import dataclass

from doefab.errors import DoefabError

__all__ = ["Application", "APPLICATIONS", "application", "of_design", "has", "design_is", "NAMES", "DESIGN_TASKS",
           "PROPERTIES"]


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
    ``build(variant, arch)`` and ``loss(pred, target)`` (imported only when a network is built)."""

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


APPLICATIONS = {a.name: a for a in (
    Application("hdr", "streak", "psnr_highlight", "dB", True,
                "high dynamic range from one exposure: a streak PSF spreads clipped highlights", camera_preset="hdr",
                network="doefab.reconstruction.hdrnet", highlights=True),
    Application("hyperspectral", "grating", "psnr", "dB", True,
                "31 spectral bands from an RGB sensor: a grating PSF disperses the coded half",
                camera_preset="hyperspectral", network="doefab.reconstruction.spectralnet", spectral=True),
    Application("depth", "half-ring", "mae", "m", False,
                "depth from one exposure: a half-ring PSF that changes with distance",
                camera_preset="depth", network="doefab.reconstruction.depthnet", depth=True),
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

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

__all__ = ["Application", "APPLICATIONS", "application", "of_design", "NAMES", "DESIGN_TASKS"]


@dataclass(frozen=True)
class Application:
    """name: the scene file's ``task``.  design_task: the DOE design task that serves it.  primary_metric: the
    reconstruction metric it is judged by first, in ``primary_unit`` ("dB", "m"); ``higher_is_better`` its
    direction.  summary: one line for help texts."""

    name: str
    design_task: str
    primary_metric: str
    primary_unit: str
    higher_is_better: bool
    summary: str


APPLICATIONS = {a.name: a for a in (
    Application("hdr", "streak", "psnr_highlight", "dB", True,
                "high dynamic range from one exposure: a streak PSF spreads clipped highlights"),
    Application("hyperspectral", "grating", "psnr", "dB", True,
                "31 spectral bands from an RGB sensor: a grating PSF disperses the coded half"),
    Application("depth", "half-ring", "mae", "m", False,
                "depth from one exposure: a half-ring PSF that changes with distance"),
)}
NAMES = tuple(APPLICATIONS)
DESIGN_TASKS = tuple(a.design_task for a in APPLICATIONS.values())


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

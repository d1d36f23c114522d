"""Pupil-to-sensor propagators behind one interface (see ``base.Route``)."""

from __future__ import annotations

from doefab.errors import DoefabError
from doefab.optics.propagators.asm import ASMRoute, angular_spectrum
from doefab.optics.propagators.base import FocalSetup, Route
from doefab.optics.propagators.fft import FFTRoute
from doefab.optics.propagators.mft import MFTRoute
from doefab.optics.propagators.spectral import SpectralRoute

__all__ = ["ASMRoute", "FFTRoute", "MFTRoute", "SpectralRoute", "FocalSetup", "Route", "angular_spectrum", "make_route", "ROUTES"]

ROUTES = ("spectral", "mft", "fft", "asm")


def make_route(route, **options) -> Route:
    """A route object from its name (``"spectral"``, ``"mft"``, ``"fft"``, ``"asm"``) or an object with the Route interface."""
    if not isinstance(route, str):
        return route
    try:
        cls = {"spectral": SpectralRoute, "mft": MFTRoute, "fft": FFTRoute, "asm": ASMRoute}[route]
    except KeyError:
        raise DoefabError(f"unknown propagation route {route!r}: choose one of {ROUTES}") from None
    import inspect

    takes = [p for p in inspect.signature(cls).parameters if p not in ("self", "args", "kwargs")]
    other = sorted(set(options) - set(takes))
    if other:
        raise DoefabError(f"unknown option {', '.join(other)}: not one of the PSF functions' (PSFPlan) nor of the "
                          f"{route!r} route's " + (f"({', '.join(takes)})" if takes else "(it has none)"))
    return cls(**options)

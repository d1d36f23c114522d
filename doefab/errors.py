"""Error types raised by doefab.

Every refusal in doefab is one of these, with a message that names the problem and the fix.
"""

from __future__ import annotations

__all__ = ["DoefabError", "SamplingError"]


class DoefabError(ValueError):
    """Bad input or an impossible request (subclass of ``ValueError``)."""


class SamplingError(DoefabError):
    """A propagator's sampling condition is violated; the message names the condition and the fix."""

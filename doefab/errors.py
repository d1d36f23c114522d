"""Error types raised by doefab.

Every refusal in doefab is one of these, with a message that names the problem and the fix. The command
line maps them to exit statuses: ``DoefabError`` (bad input, usage) 2, ``CheckFailed`` (a product that was
built but failed its own checks or verification) 3.
"""

from __future__ import annotations

__all__ = ["DoefabError", "SamplingError", "CheckFailed"]


class DoefabError(ValueError):
    """Bad input or an impossible request (subclass of ``ValueError``)."""


class SamplingError(DoefabError):
    """A propagator's sampling condition is violated; the message names the condition and the fix."""


class CheckFailed(DoefabError):
    """Something was built or read but fails its checks (a mask set that does not verify, a holder that does
    not pass); the message names the failing quantity."""

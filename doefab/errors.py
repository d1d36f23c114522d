"""Error types raised by doefab.

Every refusal in doefab is one of these, with a message that names the problem and the fix. The command
line maps them to exit statuses: ``DoefabError`` (bad input, usage) 2, ``CheckFailed`` (a product that was
built but failed its own checks or verification) 3.
"""

from __future__ import annotations

__all__ = ["DoefabError", "SamplingError", "CheckFailed", "problems_error"]


class DoefabError(ValueError):
    """Bad input or an impossible request (subclass of ``ValueError``).

    Example:

        >>> import doefab
        >>> try:
        ...     doefab.material_by_name("unobtainium")
        ... except doefab.DoefabError as exc:
        ...     print(isinstance(exc, ValueError))
        True
    """


class SamplingError(DoefabError):
    """A propagator's sampling condition is violated; the message names the condition and the fix.

    Example:

        >>> import doefab
        >>> cam = doefab.Camera(doe_pixels=64, doe_pitch=135e-6)  # 135 µm pupil samples: a 37 px alias-free field
        >>> try:
        ...     doefab.PSFPlan(cam, [550e-9], [float("inf")], kernel_size=101)
        ... except doefab.SamplingError as exc:
        ...     print(str(exc)[:37])
        [spectral] output window aliasing: th
    """


class CheckFailed(DoefabError):
    """Something was built or read but fails its checks (a mask set that does not verify, a holder that does
    not pass); the message names the failing quantity."""


def problems_error(where: object, problems: list[str]) -> DoefabError:
    """One error for every problem found in one input: a single problem on its line, several one to a line.

    Example: ``problems_error("my.toml", ["unknown key camera.x", "optics.kernel_px = 4 must be odd"])`` reads
    ``my.toml: 2 problems:`` followed by each problem on its own indented line."""
    if len(problems) == 1:
        return DoefabError(f"{where}: 1 problem: {problems[0]}")
    return DoefabError(f"{where}: {len(problems)} problems:\n" + "\n".join(f"  - {p}" for p in problems))

"""Argument types for the command line: every numeric flag is checked for type, finiteness and range
when it is parsed, and the error names the flag, the unit and the fix (argparse adds the flag's name)."""

from __future__ import annotations

import argparse
import math
import sys

from doefab.applications import has

__all__ = ["DefaultsHelp", "number", "OneLineParser", "wavelength_nm", "depth_m", "plain_name_arg",
           "design_folder", "task_design_arg", "add_device_arg"]


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line on stderr (exit status 2)."""

    def error(self, message: str):  # noqa: D401 - argparse's hook
        print(f"{self.prog}: error: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


class DefaultsHelp(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's "(default: X)" after a flag's help, except where the help tells its default itself or there is
    none to tell (None, a switch that is off)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text.lower() or action.default is None or action.default is False \
                or action.default == argparse.SUPPRESS:  # not ``in``: a default of 0 equals False
            return text
        return super()._get_help_string(action)


def number(kind=float, lo=None, hi=None, lo_open: bool = False, unit: str = "", hint: str = ""):
    """An argparse type: ``kind`` (int or float) within [lo, hi] (``lo_open``: lo excluded), finite."""
    unit_txt = f" ({unit})" if unit else ""
    what = "an integer" if kind is int else "a number"

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expects {what}{unit_txt}, got {text!r}") from None
        if kind is float and not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be a finite number{unit_txt}, got {text!r}")
        low_bad = lo is not None and (v <= lo if lo_open else v < lo)
        if low_bad or (hi is not None and v > hi):
            lo_s = "" if lo is None else (f"> {lo:g}" if lo_open else f"≥ {lo:g}")
            hi_s = "" if hi is None else f"≤ {hi:g}"
            rng = " and ".join(s for s in (lo_s, hi_s) if s)
            raise argparse.ArgumentTypeError(f"must be {rng}{unit_txt}, got {text}{hint}")
        return v

    parse.__name__ = "integer" if kind is int else "number"
    return parse


def wavelength_nm(text: str) -> float:
    """A wavelength in nanometres (100–20000 nm); a value in m, mm or µm gets the unit hint (0.55: "0.55 µm is
    550 nm: write 550")."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects a wavelength in nm, got {text!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive wavelength in nm, got {text!r}")
    if not 100 <= v <= 20000:
        from doefab.validate import unit_hint

        raise argparse.ArgumentTypeError(f"{text} nm is outside 100–20000 nm: the flag takes nanometres"
                                         f"{unit_hint(v, 100, 20000, 'nm')}")
    return v


def depth_m(text: str) -> float:
    """A point-source depth in metres (> 0, ≤ 1e6; 'inf' for a plane wave)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects a depth in metres or 'inf', got {text!r}") from None
    if math.isnan(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"must be a depth > 0 m (or inf), got {text!r}")
    if math.isfinite(v) and v > 1e6:
        raise argparse.ArgumentTypeError(f"{text} m is beyond 1000 km: write inf for a point at infinity")
    return v


def device_arg(text: str) -> str:
    """``--device``: auto, cpu, cuda or cuda:N, a device this machine has (checked when the flag is parsed)."""
    from doefab._devices import check_device
    from doefab.errors import DoefabError

    try:
        return check_device(text, "--device")
    except DoefabError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--device ")) from None


def add_device_arg(p, scene: bool = False) -> None:
    """--device: where torch computes (``scene``: the command reads a scene, whose ``device`` key it overrides)."""
    default = "the scene's device key, else " if scene else ""
    p.add_argument("--device", type=device_arg, default=None,
                   help="where torch computes: auto (a CUDA GPU when torch sees one, else the CPU), cpu, cuda or "
                        f"cuda:N (GPU N); default: {default}$DOEFAB_DEVICE, else auto")


def plain_name_arg(text: str) -> str:
    from doefab.errors import DoefabError
    from doefab.io import plain_name

    try:
        return plain_name(text, "name")
    except DoefabError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def design_folder(path):
    """``(folder, Design)`` for a design folder or a mask set (its ``design/``), validated before any work."""
    from doefab.design.design import Design, design_folder_of, designs_inside_hint, shipped_design_name
    from doefab.errors import DoefabError

    d = design_folder_of(path)
    named = shipped_design_name(path)
    if named:  # said, not silent: a folder of that name may be what was meant
        print(f"--design {path}: no such folder here; using the shipped design {named!r}", file=sys.stderr)
    if d.is_dir() and not (d / "design.json").is_file():
        raise DoefabError(f"{path} is neither a design folder nor a mask set: design.json is missing (give the folder "
                          f"holding design.json, or a mask set holding design/design.json){designs_inside_hint(d)}")
    return d, Design.load(d)


def task_design_arg(args, need_weights_dir: bool):
    """``--design`` of train/evaluate as a resolved design folder (a mask set's ``design/``), checked to be a design
    of ``--task``'s kind before any work; None for the committed design. ``need_weights_dir``: the command reads
    networks, which for another design than the committed one cannot be the shipped ones."""
    from doefab.design.design import shipped_design_name
    from doefab.errors import DoefabError
    from doefab.reconstruction.specs import check_design_task

    if not getattr(args, "design", None):
        return None
    d, design = design_folder(args.design)  # validated: a clear error before any work
    check_design_task(args.task, design.task, args.design, flag="--task", wavelengths=design.wavelengths)
    if shipped_design_name(args.design):  # the committed design by its name: the shipped networks are its own
        return None
    if need_weights_dir and getattr(args, "weights_dir", None) is None:
        raise DoefabError("--design needs --weights-dir: the shipped weights belong to the committed design")
    return d.resolve()


def add_sensor_args(p, spectral_flag: bool = True) -> None:
    """--sensor-response (``spectral_flag``), --full-well-e, --read-noise-e: the camera whose captures the
    networks see."""
    from doefab.imaging.sensor import DEFAULT_FULL_WELL_E, DEFAULT_READ_NOISE_E, FULL_WELL_RANGE_E, READ_NOISE_RANGE_E

    if spectral_flag:
        p.add_argument("--sensor-response", default=None,
                       help="hyperspectral: the RGB spectral sensitivities that form the captures: \"Canon EOS 5D "
                            "Mark II\" (default), \"Nikon D5100\", \"Sigma SD Merrill\" or a CSV (a header, then "
                            "wavelength_nm,R,G,B rows)")
    p.add_argument("--full-well-e", type=number(float, *FULL_WELL_RANGE_E, unit="electrons"),
                   default=DEFAULT_FULL_WELL_E, help="electrons at a capture value of 1 (one photodiode's full well)")
    p.add_argument("--read-noise-e", type=number(float, *READ_NOISE_RANGE_E, unit="electrons rms"),
                   default=DEFAULT_READ_NOISE_E, help="read noise in electrons rms")


def sensor_arg(args, design=None):
    """The ``imaging.sensor.Sensor`` the sensor flags name, checked before any work: a bad CSV, a response given
    to an RGB task (it forms nothing there), a response that does not cover the design's bands."""
    from doefab.errors import DoefabError
    from doefab.imaging.sensor import Sensor

    response = getattr(args, "sensor_response", None)
    task = getattr(args, "task", "depth")
    sensor = Sensor(**({"response": response} if response is not None else {}), full_well_e=args.full_well_e,
                    read_noise_e=args.read_noise_e)
    if response is not None and not has(task, "spectral") and not sensor.has_default_response():
        raise DoefabError(f"--sensor-response forms the hyperspectral task's captures only; the {task} task's "
                          f"scenes are the camera's own RGB: drop it (the noise flags apply)")
    if has(task, "spectral"):  # the design's bands within the response (the default's too)
        from doefab.reconstruction.specs import psf_pair

        try:
            sensor.rgb(psf_pair(task, design)[0].wavelengths)
        except DoefabError as exc:
            flag = "--sensor-response" if response is not None else "the design's bands (default response)"
            raise DoefabError(f"{flag}: {exc}") from None
    return sensor

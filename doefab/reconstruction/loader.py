"""``load_reconstructor``: the shipped networks of the committed designs, verified before use.

A weights file is refused — with its path and the command that retrains it — when it is missing, when its
SHA-256 differs from its metadata record (changed or corrupt), when the record names another design than the
committed one, or when torch cannot read it (always ``torch.load(..., weights_only=True)``, onto the CPU; the network
then moves to the device it runs on).
"""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import numpy as np
import torch

from doefab.applications import has
from doefab._devices import resolve_device
from doefab.errors import DoefabError
from doefab.io import read_json
from doefab.optics.psf import PSFPair, describe_bands
from doefab.reconstruction.models import build_model
from doefab.reconstruction.networks import VARIANTS
from doefab.reconstruction.specs import design_dir, get_spec, psf_pair
from doefab.reconstruction.train import model_inputs
from doefab.reconstruction.weights import WEIGHTS_FORMAT, is_shipped, renamed_state, weights_paths

__all__ = ["load_reconstructor", "Reconstructor", "weights_record", "arch_clash", "shipped_fit_problem"]


class Reconstructor:
    """A trained network with the PSF pair and design it was trained for.

    ``rec(coded, uncoded)`` → [3, H, W] HDR radiance | [31, H, W] spectra | [H, W] depth in metres (numpy in,
    numpy out; torch in, torch out); ``rec(coded, uncoded, psf=pair)`` conditions the network on another (e.g.
    measured or fabricated) PSF pair instead (depth: the proposed network's cost volume uses both halves).
    Captures that name the PSF pair they were simulated through (``simulate_captures`` gives them a ``pair``)
    are refused without ``psf=`` when that pair's bands or camera differ from the network's ``pair``: the
    network would read them through the wrong PSFs. Captures that name none (a camera's) are taken as they are.
    The network runs on ``device`` (a ``torch.device``; ``self.model`` lives there); a numpy result comes back as
    numpy, a torch result on the captures' device.
    """

    def __init__(self, task: str, variant: str, model: torch.nn.Module, pair, design_sha256: str, meta: dict,
                 device=None):
        self.device = resolve_device(device)
        self.task, self.variant, self.model = task, variant, model.to(self.device).eval()
        self.pair, self.design_sha256, self.meta = pair, design_sha256, meta

    def _psf(self, psf):
        if psf is None:
            return model_inputs(self.task, self.pair)
        if has(self.task, "depth"):
            return self._depth_psf(psf)
        coded = getattr(psf, "coded", psf)
        t = _float_tensor(coded)
        if t.ndim == 4:
            t = t[0]
        want = len(self.pair.wavelengths)
        if t.ndim != 3 or t.shape[0] != want or t.shape[-1] != t.shape[-2]:
            raise DoefabError(f"psf must be a PSF pair (or [{want}, K, K] coded PSFs) for the {want} bands of the "
                              f"{self.task} network, got {tuple(t.shape)}")
        if hasattr(psf, "wavelengths") and not np.allclose(psf.wavelengths, self.pair.wavelengths):
            raise DoefabError("the PSF pair's wavelengths differ from the ones the network was trained for")
        if not bool(torch.isfinite(t).all()) or bool((t < 0).any()):
            raise DoefabError("psf must be finite and non-negative")
        if not has(self.task, "highlights"):
            return t[None]
        # HDR: the least-squares solve needs the plain half too — the pair's, or the network's own when only
        # coded PSFs are given (the plain half carries no DOE)
        unc = getattr(psf, "uncoded", None)
        u = self.pair.uncoded[0].float() if unc is None else _float_tensor(unc)
        u = u[0] if u.ndim == 4 else u
        if tuple(u.shape) != tuple(t.shape) or not bool(torch.isfinite(u).all()) or bool((u < 0).any()):
            raise DoefabError(f"the uncoded PSF must be finite, non-negative and {tuple(t.shape)} like the coded "
                              f"one, got {tuple(u.shape)}")
        return torch.cat([t, u])[None]

    def _depth_psf(self, psf):
        """A PSF pair (both halves, the network's depth planes and wavelengths) for the cost volume."""
        if getattr(psf, "coded", None) is None or getattr(psf, "uncoded", None) is None:
            raise DoefabError("the depth network takes psf=a PSF pair with both halves (coded and uncoded)")
        if any(len(a) != len(b) or not np.allclose(a, b) for a, b in ((psf.depths, self.pair.depths),
                                                                     (psf.wavelengths, self.pair.wavelengths))):
            raise DoefabError(f"the PSF pair's depth planes or wavelengths differ from the network's "
                              f"({len(self.pair.depths)} planes {self.pair.depths[0]:g}–{self.pair.depths[-1]:g} m)")
        same = tuple(psf.coded.shape) == tuple(self.pair.coded.shape) == tuple(psf.uncoded.shape)
        t = model_inputs("depth", psf) if same else None
        if t is None or not bool(torch.isfinite(t).all()) or bool((t < 0).any()):
            raise DoefabError(f"psf must be finite, non-negative and {tuple(self.pair.coded.shape)} per half")
        return t

    def _check_system(self, captures: dict) -> None:
        """Refuse captures simulated through a PSF pair of other bands or another camera than the network's."""
        for name, x in captures.items():
            made = getattr(x, "pair", None)
            diff = self.pair.system_differences(made) if isinstance(made, PSFPair) else []
            if diff:
                raise DoefabError(
                    f"{name} was simulated through a PSF pair of {'; '.join(diff).replace('this pair', 'the network')}"
                    f": the {self.task} network reads captures through its own pair, rec.pair — simulate them through "
                    f"rec.pair (or a part of its design on its camera), or pass psf=the pair they were made through "
                    f"if it has the network's {describe_bands(self.pair.wavelengths)}")

    def __call__(self, coded, uncoded, psf=None):
        torch_in = isinstance(coded, torch.Tensor)
        if psf is None:
            self._check_system({"coded": coded, "uncoded": uncoded})
        views = []
        for name, x in (("coded", coded), ("uncoded", uncoded)):
            views.append(_capture(name, x)[None])
        if views[0].shape != views[1].shape:
            raise DoefabError(f"coded {tuple(views[0].shape[1:])} and uncoded {tuple(views[1].shape[1:])} differ in shape")
        p = self._psf(psf).to(self.device)
        with torch.no_grad():
            out = self.model(views[0].to(self.device), views[1].to(self.device), p)[0]
        return out.to(coded.device) if torch_in else out.cpu().numpy()


def _capture(name: str, x) -> torch.Tensor:
    """A [3, H, W] capture as float32, refused (with the fix) unless it holds floats in [0, 1]: the networks
    are trained on captures normalised to the sensor's white level."""
    dtype = x.dtype if isinstance(x, torch.Tensor) else np.asarray(x).dtype
    if not (dtype.is_floating_point if isinstance(dtype, torch.dtype) else dtype.kind == "f"):
        raise DoefabError(f"{name} is an integer ({dtype}) image: captures are floats in [0, 1]; divide by the "
                          f"white level (255 for 8 bits, 2**bits − 1 for raw data) first")
    t = _float_tensor(x)
    if t.ndim != 3 or t.shape[0] != 3:
        raise DoefabError(f"{name} must be a [3, H, W] capture, got {tuple(t.shape)}")
    if not bool(torch.isfinite(t).all()):
        raise DoefabError(f"{name} contains NaN or infinite values")
    lo, hi = float(t.min()), float(t.max())
    if lo < -1e-6 or hi > 1 + 1e-6:
        raise DoefabError(f"{name} holds values {lo:.4g}–{hi:.4g}: captures are in [0, 1] (0 = black, 1 = the "
                          f"sensor's clipping level); subtract the black level, divide by the white level and "
                          f"clip to [0, 1] first")
    return t


def _float_tensor(x) -> torch.Tensor:
    """A float32 tensor of an array or a tensor (detached: inference only)."""
    return torch.as_tensor(x.detach() if isinstance(x, torch.Tensor) else np.asarray(x)).float()


def _retrain(task: str, variant: str, weights_dir, design) -> str:
    """The command that makes the network the loader looks for, writing where it looks."""
    cmd = f"doefab train --task {task} --variant {variant}" + (f" --design {design}" if design is not None else "")
    if not is_shipped(weights_dir):
        return f"retrain it with: {cmd} --weights-dir {weights_dir}"
    if design is not None:
        return (f"the shipped weights belong to the committed design: train one for {design} with: {cmd} "
                f"--weights-dir NEW_FOLDER, and pass that --weights-dir")
    return f"restore it (git checkout doefab/weights) or retrain it with: {cmd} --replace-shipped"


def _refuse(path: Path, why: str, task: str, variant: str, weights_dir=None, design=None):
    raise DoefabError(f"{path}: {why}; {_retrain(task, variant, weights_dir, design)}")


def _refuse_foreign(path: Path, task: str, variant: str, weights_dir=None, design=None):
    """Refuse weights trained for another level map than ``design``'s (None: the committed design's)."""
    _refuse(path, "the weights were trained for another design than " +
            ("the committed one" if design is None else str(design)), task, variant, weights_dir, design)


def load_reconstructor(task: str, variant: str = "proposed", weights_dir: str | Path | None = None,
                       design: str | Path | None = None, other_design: bool = False, sensor=None,
                       device=None) -> Reconstructor:
    """The shipped (or ``weights_dir``'s) network for ``task`` ("hdr" | "hyperspectral" | "depth"), trained for the
    committed design (or for the design folder ``design``: candidates under comparison). ``other_design``: use
    weights trained for another design anyway (they take ``design``'s PSFs at call time; ``meta`` then says
    ``"other_design": true``) when their shapes fit it. ``sensor``: the ``imaging.sensor.Sensor`` whose captures the
    network will see (None: no check); weights trained for another sensor's noise (or, hyperspectral, response)
    are refused unless ``other_design`` (``meta`` then says ``"other_sensor": true``). ``device``: where the network
    runs ("auto", "cpu", "cuda", "cuda:N"; None: the current default, ``doefab._devices.default_device``); the
    weights load onto the CPU (``map_location``, ``weights_only=True``) and move there.

    Example:
        The shipped depth network, which is told the committed half-ring's PSFs at its 17 planes:

        >>> import doefab
        >>> rec = doefab.load_reconstructor("depth")
        >>> rec.task, rec.variant, len(rec.pair.depths)
        ('depth', 'proposed', 17)
    """
    get_spec(task)
    device = resolve_device(device)
    pt, meta, data = _read_weights(task, variant, weights_dir, design)
    who = (task, variant, weights_dir, design)
    pair, sha = psf_pair(task, design)
    foreign = meta["design_levels_sha256"] != sha
    if foreign and not other_design:
        _refuse_foreign(pt, *who)
    if foreign:
        from doefab.reconstruction.train import arch_for_design

        if clash := arch_clash(meta["arch"], arch_for_design(task, pair)):
            raise DoefabError(f"{pt}: trained for another design, whose networks cannot take {design}'s PSFs "
                              f"({'; '.join(clash)}); {_retrain(task, variant, weights_dir, design)}")
        meta = {**meta, "other_design": True}
    meta = _check_sensor(meta, sensor, other_design, pt, who)
    try:
        state = torch.load(io.BytesIO(data), weights_only=True, map_location="cpu")
        model = build_model(task, variant, meta["arch"])
        model.load_state_dict(renamed_state(state))
    except Exception as exc:  # noqa: BLE001 - unpickling, zip or key errors all mean an unusable file
        _refuse(pt, f"torch cannot load it ({exc.__class__.__name__})", *who)
    return Reconstructor(task, variant, model, pair, sha, meta, device)


def arch_clash(arch: dict, need: dict) -> list[str]:
    """What of ``need`` (``train.arch_for_design``: a design's planes, depth range, bands) a network built as
    ``arch`` cannot take, one phrase each (empty: it takes them): another count of planes for a cost volume (one
    channel each), a farthest plane beyond the depths it outputs, other bands.

    Example: ``arch_clash({"cost_volume": True, "planes": 17, "max_depth_m": 6.0}, {"planes": 17, "max_depth_m":
    36.0})`` → ``["max_depth_m: it outputs depths up to 6 m, the design's farthest plane lies at 30 m"]``."""
    out = []
    for k, v in need.items():
        have = arch.get(k, _DEFAULT_ARCH.get(k))
        if k == "planes" and not arch.get("cost_volume"):
            continue  # only the cost volume has one channel per plane
        if k == "max_depth_m":
            if have is not None and v / 1.2 > float(have) + 1e-9:
                out.append(f"max_depth_m: it outputs depths up to {float(have):g} m, the design's farthest plane lies "
                           f"at {v / 1.2:g} m")
        elif have != v:
            text = _bands if k == "wavelengths_m" else str
            out.append(f"{k}: {text(have)} for the network, {text(v)} for the design")
    return out


def _bands(lams) -> str:
    """A record's bands for a message (None: the hyperspectral scenes' own)."""
    if lams is None:
        from doefab.reconstruction.data import HS_WAVELENGTHS_M

        lams = HS_WAVELENGTHS_M
    nm = [float(w) * 1e9 for w in lams]
    return f"{len(nm)} band(s) {min(nm):.4g}–{max(nm):.4g} nm"


def shipped_fit_problem(task: str, wavelengths, depths) -> str:
    """Why the shipped ``task`` networks cannot take a design on ``wavelengths`` and ``depths`` (metres), told its
    PSFs (``load_reconstructor(other_design=True)``), or "" when they can: what a scene with
    ``reconstruction.weights = "shipped-anyway"`` is checked by before its design is computed.

    Example: ``shipped_fit_problem("depth", [656e-9, 589e-9, 486e-9], [3.0, 30.0])`` names the proposed
    network's 17 planes and its 6 m reach."""
    from doefab.reconstruction.train import arch_for_bands

    need = arch_for_bands(task, wavelengths, depths)
    for variant in VARIANTS:
        pt, meta, _ = _read_weights(task, variant, None, None)
        if clash := arch_clash(meta["arch"], need):
            return f"the shipped {task} {variant} network cannot take this design's PSFs ({'; '.join(clash)})"
    return ""


def weights_record(task: str, variant: str = "proposed", weights_dir: str | Path | None = None,
                   design: str | Path | None = None, sensor=None) -> dict:
    """The metadata record of the shipped (or ``weights_dir``'s) ``task``/``variant`` network, checked as
    ``load_reconstructor`` checks it (``other_design`` off), but before any PSF is computed (a command calls it
    before it claims its output folder): the folder is a folder, the weights file and its record exist, the record
    is valid JSON of this format, task and variant, the file's SHA-256 is the record's, the weights were trained for
    the level map of ``design`` (a design folder; None: the committed design) and, with ``sensor``, for that
    sensor's noise (hyperspectral: and response; whether the response covers the design's bands is left to
    ``load_reconstructor``, which computes the bands' PSFs). One DoefabError names the file and the fix.

    Example:
        >>> from doefab.reconstruction.loader import weights_record
        >>> weights_record("depth")["variant"]
        'proposed'
    """
    from doefab.design.design import Design
    from doefab.fabrication.levels import levels_sha256

    pt, meta, _ = _read_weights(task, variant, weights_dir, design)
    if meta["design_levels_sha256"] != levels_sha256(Design.load(design or design_dir(task)).levels):
        _refuse_foreign(pt, task, variant, weights_dir, design)
    return _check_sensor(meta, sensor, False, pt, (task, variant, weights_dir, design), bands=False)


def _read_weights(task: str, variant: str, weights_dir, design) -> tuple[Path, dict, bytes]:
    """(weights file, its record, its bytes), refused unless they are as ``weights_record`` states."""
    get_spec(task)
    if variant not in VARIANTS:
        raise DoefabError(f"variant must be one of {VARIANTS}, got {variant!r}")
    if weights_dir is not None and Path(weights_dir).is_file():
        raise DoefabError(f"weights_dir {weights_dir} is a file: give the folder holding {task}_{variant}.pt")
    pt, meta_path = weights_paths(task, variant, weights_dir)
    who = (task, variant, weights_dir, design)
    if not pt.is_file() or not meta_path.is_file():
        _refuse(pt, "no weights (or no metadata record beside them)", *who)
    # a record training would not recognise as its own it never overwrites: the fix moves the files away first
    away = "" if weights_dir is None else f" (training never replaces a record it cannot read: move it and {pt.name} " \
                                           f"out of {weights_dir} first)"
    try:
        meta = read_json(meta_path)
    except (ValueError, UnicodeDecodeError):
        _refuse(meta_path, "the metadata record is not valid JSON" + away, *who)
    need = ("format", "task", "variant", "design_levels_sha256", "arch", "weights_sha256")
    if not isinstance(meta, dict) or any(k not in meta for k in need) or meta.get("format") != WEIGHTS_FORMAT:
        _refuse(meta_path, f"the metadata record lacks {list(need)}" + away, *who)
    if (meta["task"], meta["variant"]) != (task, variant):
        _refuse(meta_path, f"the record is for {meta['task']}/{meta['variant']}" + away, *who)
    data = pt.read_bytes()
    if hashlib.sha256(data).hexdigest() != meta["weights_sha256"]:
        _refuse(pt, "the file's SHA-256 differs from its metadata record (changed or corrupt)", *who)
    return pt, meta, data


def _check_sensor(meta: dict, sensor, anyway: bool, pt: Path, who: tuple, bands: bool = True) -> dict:
    """``meta``, marked ``other_sensor`` when the weights were trained for another sensor and ``anyway``; refused
    when they were and not ``anyway``. ``bands``: also refuse a response that misses the design's bands (it
    computes the design's PSF pair)."""
    if sensor is None:
        return meta
    task, variant, weights_dir, design = who
    if bands and has(task, "spectral"):  # a response that misses the bands: no network can be trained for it either
        sensor.rgb(psf_pair(task, design)[0].wavelengths)
    diff = sensor.differs_from(meta.get("sensor"), spectral=has(task, "spectral"))
    if not diff:
        return meta
    if not anyway:
        flags = ("--sensor-response, " if has(task, "spectral") else "") + "--full-well-e and --read-noise-e"
        raise DoefabError(f"{pt}: trained for another sensor ({'; '.join(diff)}): train networks for this camera "
                          f"with doefab train --task {task} --variant {variant} and its {flags} into a --weights-dir")
    return {**meta, "other_sensor": True}


_DEFAULT_ARCH = {"planes": 17, "wavelengths_m": None}  # what records without these entries were built with

"""The measured-data validation set: split ``real``, scenes whose content doefab did not make.

Every network is scored on it under the same honest captures as the synthetic splits (``doefab evaluate --split
real``); none of it is in training (``tests/reconstruction/test_realdata.py``). ``SOURCES`` is its table: what is
measured, where it comes from, its license and what it is used for. Per task:

- **hdr** — six OpenEXR sample photographs' radiance maps (``doefab/measured/hdr_radiance.npz``, written by
  ``scripts/measured_hdr.py``): a crop at a drawn place, exposed so that a drawn 1–5 % of its pixels lie above the
  half-exposure capture's clip (2.0, as the synthetic scenes; the exposure is the camera's choice, the highlights'
  shapes, sizes and contrasts are the photograph's), capped at 2^8.
- **depth** — nine scenes of the Middlebury 2014 datasets: the *Motorcycle* as scikit-image ships it, and eight
  more from the Middlebury Stereo Evaluation v3's quarter-resolution training set (``doefab/measured/
  middlebury_depth.npz``, written by ``scripts/measured_depth.py``; the scenes it leaves out and why are in its
  docstring). Each sample draws a scene, then a crop: the left image (sRGB decoded to linear, the synthetic scenes'
  exposure range) and its ground-truth disparity turned into metres with the scene's published calibration,
  Z = f·B / (d + doffs): 0.98–5.02 m over the nine, the shipped design's 1–5 m, so used as measured (clipped to the
  design's planes). The 0–10 % of a scene's pixels without ground truth take their nearest measured neighbour's
  depth to be rendered and are left out of the scores (the target holds NaN there).
- **hyperspectral** — measured light of a family that no split, no synthetic draw and no illuminant library holds:
  two displays' measured RGB primaries (``colour.MSDS_DISPLAY_PRIMARIES``) mixed at drawn weights, an RGB emitter
  (colour-science's measured incandescent lamps are not used: both lie within 0.02 of the library's illuminant A,
  the rule by which ``spectra`` leaves a light out as a library member); the reflectances are the validation split's measured set (NIST CQS), laid out
  along the validation photographs' edges as in the synthetic scenes (that layout is doefab's).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from doefab.applications import has

__all__ = ["SOURCES", "Source", "hdr_real_sample", "depth_real_sample", "real_light", "real_lights",
           "drawn_depth_scene", "MOTORCYCLE", "HDR_FILE", "HDR_SHA256", "DEPTH_FILE", "DEPTH_SHA256", "check_side",
           "depth_scenes", "measured_depth"]

HDR_FILE = Path(__file__).resolve().parents[1] / "measured" / "hdr_radiance.npz"
HDR_SHA256 = "159a5e0a1118c1c891dc5e0700d39f341430fa9070f26feddeb91a3272da50da"  # as scripts/measured_hdr.py wrote it
DEPTH_FILE = Path(__file__).resolve().parents[1] / "measured" / "middlebury_depth.npz"
# as scripts/measured_depth.py wrote it
DEPTH_SHA256 = "5e30d0ce2838ea127b683b53667d4b51f3a0bcc66ef04e0b5e11cf9eabd499cb"
# Middlebury 2014 Motorcycle at scikit-image's quarter resolution (skimage.data.stereo_motorcycle's docstring)
MOTORCYCLE = {"focal_px": 994.978, "baseline_m": 0.193001, "doffs_px": 31.086}
DISPLAYS = ("Typical CRT Brainard 1997", "Apple Studio Display")
CLIP = 2.0  # where the half-exposure capture of a scene of value 1 clips (data.hdr_sample's saturate_above)
PEAK = 256.0


@dataclass(frozen=True)
class Source:
    task: str
    name: str
    measured: str
    origin: str
    license: str
    use: str


SOURCES = (
    Source("hdr", "OpenEXR sample images: Cannon, Desk, MtTamWest, StillLife, CandleGlass, GoldenGate",
           "radiance maps of photographed scenes (multi-exposure HDR, Rec. 709 primaries)",
           "github.com/AcademySoftwareFoundation/openexr-images (ScanLines/, Tiles/)",
           "BSD-3-Clause, © Industrial Light & Magic and the OpenEXR contributors (doefab/measured/"
           "openexr-images-COPYING.txt)", "scene radiance: crops, exposure drawn, capped at 2^8"),
    Source("depth", "Middlebury 2014 Motorcycle (Scharstein et al., GCPR 2014), as scikit-image ships it",
           "ground-truth disparity (structured light) and the left image",
           "skimage.data.stereo_motorcycle (scikit-image's data files)",
           "Middlebury stereo data: free for research use with citation of Scharstein et al. 2014",
           "one of the nine depth scenes: depth in metres from the published calibration; the image as the scene's "
           "radiance (it is also one of the synthetic validation split's photographs, never a training one)"),
    Source("depth", "Middlebury 2014 Adirondack, Jadeplant, Piano, Playroom, Playtable, Recycle, Shelves, Vintage "
           "(Scharstein et al., GCPR 2014), the Middlebury Stereo Evaluation v3's quarter-resolution training set",
           "ground-truth disparity (structured light) and the left image",
           "vision.middlebury.edu/stereo/submit3 (MiddEval3 trainingQ), read from the copy in "
           "github.com/Homay0118/DDL_demo (69cc478); doefab/measured/middlebury_depth.npz names each file's SHA-256",
           "Middlebury: permission to use and publish the images and disparity maps, citing Scharstein et al. 2014",
           "eight of the nine depth scenes: depth in metres from each scene's published calibration; the image as "
           "the scene's radiance (in no split)"),
    Source("hyperspectral", "measured display primaries: Typical CRT (Brainard 1997), Apple Studio Display",
           "emission spectra of each display's R, G, B primaries", "colour-science: colour.MSDS_DISPLAY_PRIMARIES",
           "BSD-3-Clause (colour-science)", "scene light: the three primaries at drawn weights"),
)


def _check_file(path: Path, sha256: str, script: str) -> None:
    """A DoefabError unless the measured file ``path`` is the one ``script`` wrote (its SHA-256 is ``sha256``)."""
    import hashlib

    from doefab.errors import DoefabError

    if hashlib.sha256(path.read_bytes()).hexdigest() != sha256:
        raise DoefabError(f"{path} is not the file {script} wrote (SHA-256 differs): restore it from the package "
                          f"(git checkout, or reinstall doefab)")


@functools.lru_cache(maxsize=1)
def _hdr_maps() -> tuple[np.ndarray, ...]:
    _check_file(HDR_FILE, HDR_SHA256, "scripts/measured_hdr.py")
    with np.load(HDR_FILE) as z:
        names = list(json.loads(str(z["sources"])))
        return tuple(np.asarray(z[n], np.float32) for n in names)


def check_side(task: str, size: int, margin: int = 0) -> None:
    """A DoefabError unless every measured map of ``task`` holds a scene of ``size`` pixels with ``margin`` more
    on each side (the PSF's half window): checked before any capture is made."""
    from doefab.errors import DoefabError

    if has(task, "highlights"):
        small = min(min(m.shape[:2]) for m in _hdr_maps())
    elif has(task, "depth"):
        small = min(min(depth.shape) for _, _, depth, _ in depth_scenes())
    else:
        return  # hyperspectral: the validation photographs' layout, any size
    if size + 2 * margin > small:
        raise DoefabError(f"a {size}-px scene with its {margin}-px PSF margin on each side is larger than the "
                          f"smallest measured {task} map ({small} px on its short side): evaluate the real split "
                          f"at --size {small - 2 * margin} or less")


def _crop(rng, shape, size: int) -> tuple[slice, slice]:
    h, w = shape[:2]
    y, x = int(rng.integers(0, h - size + 1)), int(rng.integers(0, w - size + 1))
    return slice(y, y + size), slice(x, x + size)


def hdr_real_sample(rng: np.random.Generator, size: int) -> np.ndarray:
    """[3, S, S] radiance from a measured HDR map: a drawn map and crop, exposed so that a drawn 1–5 % of its
    pixels exceed ``CLIP`` in some channel (fewer where the crop's range is too small), capped at ``PEAK``."""
    check_side("hdr", size)
    maps = _hdr_maps()
    m = maps[int(rng.integers(len(maps)))]
    ys, xs = _crop(rng, m.shape, size)
    crop = m[ys, xs].transpose(2, 0, 1)
    bright = crop.max(axis=0)
    level = float(np.quantile(bright, 1.0 - rng.uniform(0.01, 0.05)))
    gain = CLIP / max(level, 1e-6)
    return np.minimum(crop * gain, PEAK).astype(np.float32)


def measured_depth(srgb: np.ndarray, disparity: np.ndarray, focal_px: float, baseline_m: float,
                   doffs_px: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(linear image [H, W, 3] float32, depth [H, W] metres with every pixel filled, whether measured [H, W]) of an
    8-bit sRGB image and its disparity in pixels (NaN where unmeasured): Z = f·B / (d + doffs) at each measured
    pixel, each other pixel the depth of a nearest measured one.

    Example: ``measured_depth(img, disp, 994.978, 0.193001, 31.086)`` for the quarter-resolution Motorcycle."""
    from scipy.ndimage import distance_transform_edt

    known = np.isfinite(disparity)
    z = np.where(known, focal_px * baseline_m / (np.where(known, disparity, 0.0) + doffs_px), np.nan)
    idx = distance_transform_edt(~known, return_distances=False, return_indices=True)
    img = (np.asarray(srgb, np.float32) / 255.0) ** 2.2
    return img, z[idx[0], idx[1]].astype(np.float32), known


@functools.lru_cache(maxsize=1)
def _motorcycle() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(linear image [H, W, 3], depth [H, W] metres with every pixel filled, whether measured [H, W])."""
    from skimage.data import stereo_motorcycle

    left, _, disp = stereo_motorcycle()
    return measured_depth(left, disp, **MOTORCYCLE)


@functools.lru_cache(maxsize=1)
def _middlebury() -> tuple[tuple[str, np.ndarray, np.ndarray, np.ndarray], ...]:
    """(name, linear image, depth, measured) of each scene ``DEPTH_FILE`` holds, in its order."""
    import imageio.v3 as iio

    _check_file(DEPTH_FILE, DEPTH_SHA256, "scripts/measured_depth.py")
    out = []
    with np.load(DEPTH_FILE) as z:
        scale = float(z["disparity_scale"])
        for name, src in json.loads(str(z["sources"])).items():
            steps = np.asarray(iio.imread(z[f"{name}_disparity_png"].tobytes()), np.float64)
            disp = np.where(steps > 0, steps / scale, np.nan)
            out.append((name, *measured_depth(iio.imread(z[f"{name}_image_png"].tobytes()), disp,
                                              **src["calibration"])))
    return tuple(out)


def depth_scenes() -> tuple[tuple[str, np.ndarray, np.ndarray, np.ndarray], ...]:
    """The measured depth scenes, each (name, linear image [H, W, 3], depth [H, W] metres with every pixel filled,
    whether measured [H, W]): the Motorcycle, then ``DEPTH_FILE``'s."""
    return (("Motorcycle", *_motorcycle()), *_middlebury())


def drawn_depth_scene(rng: np.random.Generator) -> int:
    """The index in ``depth_scenes()`` of the measured scene a sample's generator draws (its first draw in
    :func:`depth_real_sample`): ``drawn_depth_scene(data.sample_rng("real", i))`` names scene ``i``'s source.

    Example: ``depth_scenes()[drawn_depth_scene(sample_rng("real", 0))][0]`` → the scene's name."""
    return int(rng.integers(len(depth_scenes())))


def depth_real_sample(rng: np.random.Generator, size: int, near: float, far: float):
    """(scene [3, S, S] radiance, depth to render [S, S] metres, measured [S, S] bool): a crop of a drawn measured
    scene (``depth_scenes``), its depth clipped to [``near``, ``far``]."""
    check_side("depth", size)
    _, img, depth, known = depth_scenes()[drawn_depth_scene(rng)]
    ys, xs = _crop(rng, depth.shape, size)
    gain = rng.uniform(0.8, 1.8)  # the synthetic depth scenes' exposure range
    scene = img[ys, xs].transpose(2, 0, 1) * gain
    return (np.ascontiguousarray(scene, np.float32), np.clip(depth[ys, xs], near, far).astype(np.float32),
            known[ys, xs].copy())


@functools.lru_cache(maxsize=1)
def real_lights() -> dict:
    """{display: [3, 31] its measured R, G, B primaries on the 31 bands, each peak 1}."""
    import colour

    from doefab.reconstruction.bands import on_bands

    out = {}
    for name in DISPLAYS:
        msd = colour.characterisation.MSDS_DISPLAY_PRIMARIES[name]
        rows = np.array([on_bands(sd) for sd in msd.to_sds()])
        out[name] = np.clip(rows, 0, None) / rows.max(axis=1, keepdims=True)
    return out


def real_light(rng: np.random.Generator) -> np.ndarray:
    """[31] one scene's light, peak 1: a drawn display's primaries at weights drawn in [0.2, 1]."""
    rows = real_lights()[DISPLAYS[int(rng.integers(len(DISPLAYS)))]]
    e = rng.uniform(0.2, 1.0, len(rows)) @ rows
    return (e / e.max()).astype(np.float64)


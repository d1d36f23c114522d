"""Seeded procedural training data for the three tasks (nothing is downloaded at run time).

Every sample is drawn from its own ``numpy.random.SeedSequence([split seed, index])``, and the three splits
never share content: each of scikit-image's photographs (``skimage.data``, converted to linear radiance)
belongs to one split only (``IMAGES``), and so does each measured reflectance family and each family of light
but the illuminant library the proposed network searches (``spectra``; ``tests/reconstruction/test_splits.py``
checks every pair of splits). A fourth split, ``final`` (the final test set), draws new scenes from the test
split's content (``CONTENT``). A fifth, ``real``, is measured data doefab did not make (``realdata``): it
validates, it is never trained on. A third of the textures are procedural (smooth noise, stripes, checkers), so the
networks see natural image statistics and sharp synthetic edges. ``split_digest`` names what makes the scenes.

Why these are fair stand-ins for the paper's datasets:
- HDR (the paper's § 4.3 uses HDR photographs): textured scenes at ordinary exposure plus highlights — light sources,
  specular blobs and small bright points — scaled so 1–5 % of the pixels saturate the plain (uncoded)
  half-exposure capture, with values up to 2^8, the paper's peak.
- Hyperspectral (the paper's § 4.4 uses measured hyperspectral images): 31 bands 400–700 nm built from measured
  reflectance spectra shipped by colour-science (and smooth synthetic ones in training) under measured and
  synthesised light (``spectra``), laid out in regions following the edges of real photographs, with shading.
- Depth (the paper's § 4.5 uses rendered scenes, 1–5 m): layered scenes — a far background, often a receding ground
  plane, and 2–6 occluding textured objects at random depths — with a metric depth map.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np

from doefab.applications import has
from doefab.reconstruction.bands import HS_WAVELENGTHS_M, illuminant_spectra

__all__ = ["SPLIT_SEEDS", "PART_SEEDS", "SYNTHETIC", "CONTENT", "sample_rng", "texture", "hdr_sample", "spectral_sample",
           "depth_sample", "illuminant_spectra", "HS_WAVELENGTHS_M", "IMAGES", "split_images", "resample_bands",
           "split_digest", "split_components", "CONTENT_COMPONENTS", "real_components"]

SPLIT_SEEDS = {"train": 1_000_003, "val": 2_000_029, "test": 3_000_017, "final": 4_000_037, "real": 5_000_011}
PART_SEEDS = {"train": 11, "val": 22, "test": 33, "final": 44, "real": 55}  # a split's parts are never another's
SYNTHETIC = ("train", "val", "test", "final")  # the splits of generated scenes; "real": ``realdata``, measured
PART_MODEL = ("optics", "fabrication", "tolerance")  # the subpackages whose code computes a fabricated part's PSF
# The content pool each split draws its scenes from. "final" is the final test set, made after every earlier read
# of the test split (benchmarks/results/test_split_reads.md) and read only by ``doefab evaluate --split final``:
# new scenes (its own seed) through new fabricated parts (its own part seed), drawn from the test split's pool —
# its photographs, reflectance families and lights, which earlier test reads saw (scikit-image ships no further
# colour photograph to give it content of its own).
# "real", the measured-data validation set (``realdata``), takes the validation pool where it needs one (the
# hyperspectral scenes' reflectances and layouts; their light is measured, of a family no split holds).
CONTENT = {"train": "train", "val": "val", "test": "test", "final": "test", "real": "val"}
_PACKAGE = Path(__file__).resolve().parents[1]  # doefab/
# scikit-image's photographs, each in one split only (cat and chelsea are the same picture: chelsea, test)
IMAGES = {"train": ("astronaut", "camera", "rocket", "coins", "moon", "brick", "grass", "hubble_deep_field", "page",
                    "clock", "cell", "text"),
          "val": ("immunohistochemistry", "gravel", "stereo_motorcycle"),
          "test": ("coffee", "chelsea", "colorwheel", "retina")}


def _generated_only(split: str) -> None:
    if split not in SYNTHETIC:
        from doefab.errors import DoefabError

        raise DoefabError(f"split {split!r} has no generated HDR or depth scenes: the measured set's come from "
                          f"doefab.reconstruction.realdata (specs.render_scene draws them)")


def sample_rng(split: str, index: int) -> np.random.Generator:
    """The generator of sample ``index`` of ``split`` (train / val / test)."""
    return np.random.default_rng(np.random.SeedSequence([SPLIT_SEEDS[split], int(index)]))


def split_images(split: str) -> tuple:
    """The split's photographs as linear-radiance [H, W, 3] arrays (for content checks and benchmarks)."""
    return _images(CONTENT[split])


@functools.lru_cache(maxsize=None)
def _images(pool: str) -> tuple:
    import skimage.data as skd

    names = IMAGES[pool]
    out = []
    for name in names:
        a = getattr(skd, name)()
        a = a[0] if isinstance(a, tuple) else a
        a = np.asarray(a, np.float32) / 255.0
        if a.ndim == 2:
            a = np.repeat(a[..., None], 3, axis=2)
        out.append(np.ascontiguousarray(a[..., :3] ** 2.2))  # sRGB-ish to linear
    return tuple(out)


def _smooth_noise(rng, size: int, scale: float) -> np.ndarray:
    f = np.fft.fftfreq(size)
    r = np.hypot(*np.meshgrid(f, f, indexing="ij"))
    spec = (rng.normal(size=(size, size)) + 1j * rng.normal(size=(size, size))) * np.exp(-(r * scale) ** 2)
    n = np.real(np.fft.ifft2(spec))
    return (n - n.min()) / (np.ptp(n) + 1e-12)


def texture(rng: np.random.Generator, size: int, split: str) -> np.ndarray:
    """[3, size, size] linear radiance in [0, 1]: a random crop of a shipped photograph, or a procedural one."""
    if rng.random() < 2 / 3:
        imgs = _images(CONTENT[split])
        img = imgs[rng.integers(len(imgs))]
        h, w = img.shape[:2]
        step = int(rng.choice([1, 1, 2])) if min(h, w) >= 2 * size else 1
        crop = size * step
        if crop > min(h, w):  # small images: tile
            reps = int(np.ceil(crop / min(h, w)))
            img = np.tile(img, (reps, reps, 1))
            h, w = img.shape[:2]
        y, x = rng.integers(0, h - crop + 1), rng.integers(0, w - crop + 1)
        t = img[y:y + crop:step, x:x + crop:step]
        t = np.rot90(t, int(rng.integers(4)))
        if rng.random() < 0.5:
            t = t[:, ::-1]
        t = np.moveaxis(t, 2, 0) * rng.uniform(0.6, 1.4, (3, 1, 1))
    else:
        kind = rng.integers(3)
        if kind == 0:
            t = np.stack([_smooth_noise(rng, size, rng.uniform(3, 40)) for _ in range(3)])
        elif kind == 1:
            yy, xx = np.mgrid[:size, :size]
            a, period = rng.uniform(0, np.pi), rng.uniform(3, 30)
            s = (np.sin((xx * np.cos(a) + yy * np.sin(a)) * 2 * np.pi / period) > 0).astype(np.float32)
            t = s[None] * rng.uniform(0.2, 1, (3, 1, 1)) + (1 - s[None]) * rng.uniform(0, 0.5, (3, 1, 1))
        else:
            yy, xx = np.mgrid[:size, :size]
            cell = int(rng.integers(4, 24))
            s = (((yy // cell) + (xx // cell)) % 2).astype(np.float32)
            t = s[None] * rng.uniform(0.2, 1, (3, 1, 1)) + (1 - s[None]) * rng.uniform(0, 0.5, (3, 1, 1))
    return np.clip(np.ascontiguousarray(t), 0, 1).astype(np.float32)


def _highlight(rng, size: int, split: str) -> tuple[np.ndarray, np.ndarray]:
    """One highlight: (mask [S, S], radiance [3, S, S] inside it). Three kinds, because real highlights are
    rarely flat: a flat disc (a uniformly bright source), a lamp whose radiance falls off from a peak of up to
    2^8 (a bulb, the sun through haze), and a window or sunlit patch that keeps a texture's structure at
    2^1.5–2^7 times the scene's exposure."""
    yy, xx = np.ogrid[:size, :size]
    cy, cx = rng.uniform(0, size, 2)
    tint = rng.uniform(0.7, 1.0, (3, 1, 1))
    kind = rng.random()
    if kind < 0.3:  # flat disc, as small as a point
        r = rng.uniform(0.5, max(1.0, 0.06 * size)) if rng.random() < 0.7 else rng.uniform(0.3, 1.2)
        m = (yy - cy) ** 2 + (xx - cx) ** 2 <= r * r
        value = np.broadcast_to(2.0 ** rng.uniform(1.2, 8.0) * tint, (3, size, size))
    elif kind < 0.65:  # lamp: peak · (1 + (r / r0)²)^-1.5, cut where it falls below the scene's exposure
        r0 = rng.uniform(0.5, max(1.0, 0.03 * size))
        peak = 2.0 ** rng.uniform(3.0, 8.0)
        prof = peak * (1.0 + ((yy - cy) ** 2 + (xx - cx) ** 2) / r0 ** 2) ** -1.5
        m, value = prof > 0.5, prof[None] * tint
    else:  # textured window
        h, w = rng.uniform(0.02, 0.12, 2) * size
        m = (np.abs(yy - cy) <= h / 2) & (np.abs(xx - cx) <= w / 2)
        value = 2.0 ** rng.uniform(1.5, 7.0) * (0.15 + 0.85 * texture(rng, size, split)) * tint
    if not m.any():  # smaller than a pixel: the pixel under its centre
        m = np.zeros((size, size), bool)
        m[int(cy) % size, int(cx) % size] = True
    return m, value


def hdr_sample(rng: np.random.Generator, size: int, split: str, saturate_above: float = 2.0) -> np.ndarray:
    """[3, S, S] HDR radiance: texture at ordinary exposure plus highlights (``_highlight``), 1–5 % of pixels
    above ``saturate_above`` (2.0: where a half-exposure capture of value 1 clips), peaks up to 2^8."""
    _generated_only(split)
    scene = texture(rng, size, split) * rng.uniform(0.3, 1.0)
    target = rng.uniform(0.01, 0.05) * size * size
    covered = np.zeros((size, size), bool)
    tries, max_tries = 0, 40 * max(1, (size // 128) ** 2)
    while covered.sum() < target and tries < max_tries:
        tries += 1
        m, value = _highlight(rng, size, split)
        lit = np.where(m[None], np.maximum(scene, value), scene)
        now = (lit > saturate_above).any(axis=0)
        if now.mean() > 0.05 and covered.any():  # too large for what is left: draw another
            continue
        scene, covered = lit, now
    return np.minimum(scene, 256.0).astype(np.float32)


def spectral_sample(rng: np.random.Generator, size: int, split: str, light: str | None = None) -> np.ndarray:
    """[31, S, S] spectral radiance (400–700 nm): reflectances of the split (measured, and in training also
    synthetic) in regions that follow a real image's edges, shaded, under one light (peak 1): ``light`` is
    "in-library" or "out-of-library" (``spectra.light_kind``; default: the split's own)."""
    from doefab.reconstruction.spectra import reflectances, scene_illuminant, synthetic_reflectance

    refl = reflectances(CONTENT[split])
    k = int(rng.integers(3, 9))
    lum = texture(rng, size, split).mean(axis=0)
    edges = np.quantile(lum, np.linspace(0, 1, k + 1)[1:-1])
    regions = np.digitize(lum, edges)
    picks = refl[rng.choice(len(refl), size=k, replace=len(refl) < k)]
    if split == "train":  # half the regions synthetic: the networks must not learn a few dozen spectra
        picks = np.array([synthetic_reflectance(rng) if rng.random() < 0.5 else p for p in picks])
    shading = 0.4 + 0.6 * _smooth_noise(rng, size, rng.uniform(2, 10))
    if split == "real":
        from doefab.reconstruction.realdata import real_light

        e = real_light(rng)
    else:
        e = scene_illuminant(rng, CONTENT[split], light)
    scene = picks[regions].transpose(2, 0, 1) * shading[None] * e[:, None, None]
    # exposure: the brightest pixel's band-mean radiance is 0.6–1.2 (a flat spectrum of 1 fills an RGB channel)
    return (scene * rng.uniform(0.6, 1.2) / max(scene.mean(axis=0).max(), 1e-6)).astype(np.float32)


def resample_bands(values: np.ndarray, wavelengths_m, axis: int = 0) -> np.ndarray:
    """``values`` known on the 31 bands 400–700 nm (``HS_WAVELENGTHS_M``, along ``axis``) at ``wavelengths_m``
    (linear in wavelength; the bands must lie within 400–700 nm). The same array when they are those bands."""
    want = np.asarray(wavelengths_m, np.float64)
    grid = np.asarray(HS_WAVELENGTHS_M)
    if want.shape == grid.shape and np.allclose(want, grid, rtol=0, atol=1e-12):
        return values
    if want.min() < grid[0] - 1e-12 or want.max() > grid[-1] + 1e-12:
        from doefab.errors import DoefabError

        raise DoefabError(f"bands {want.min() * 1e9:.0f}–{want.max() * 1e9:.0f} nm reach outside 400–700 nm, where "
                          f"the scenes' reflectances and lights are known: keep the bands within it")
    v = np.moveaxis(np.asarray(values), axis, -1)
    idx = np.clip(np.searchsorted(grid, want) - 1, 0, len(grid) - 2)
    t = ((want - grid[idx]) / (grid[idx + 1] - grid[idx])).astype(v.dtype if v.dtype.kind == "f" else np.float64)
    out = v[..., idx] * (1 - t) + v[..., idx + 1] * t
    return np.moveaxis(out, -1, axis)


def _shape_mask(rng, size):
    yy, xx = np.mgrid[:size, :size]
    cy, cx = rng.uniform(0, size, 2)
    ry, rx = rng.uniform(0.08, 0.4, 2) * size
    kind = rng.integers(3)
    if kind == 0:
        return ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1
    if kind == 1:
        return (np.abs(yy - cy) <= ry) & (np.abs(xx - cx) <= rx)
    a = rng.uniform(0, np.pi)
    u = (xx - cx) * np.cos(a) + (yy - cy) * np.sin(a)
    v = -(xx - cx) * np.sin(a) + (yy - cy) * np.cos(a)
    return (np.abs(u) <= rx) & (np.abs(v) <= ry * 0.5)


def depth_sample(rng: np.random.Generator, size: int, split: str, near: float = 1.0, far: float = 5.0):
    """(scene [3, S, S] radiance, depth [S, S] metres): background (often a receding ground plane) and 2–6
    occluding textured objects between ``near`` and ``far``, drawn far to near."""
    _generated_only(split)
    gain = rng.uniform(0.8, 1.8)  # exposure: radiance up to ~2, so a half-exposure capture reaches ~1
    scene = texture(rng, size, split) * gain
    z_bg = rng.uniform(0.7 * far, far)
    depth = np.full((size, size), z_bg, np.float32)
    if rng.random() < 0.6:  # ground plane: nearer toward the bottom rows
        z_near = rng.uniform(near, 0.6 * far)
        horizon = int(rng.integers(size // 4, 3 * size // 4))
        rows = np.arange(size)
        t = np.clip((rows - horizon) / max(size - 1 - horizon, 1), 0, 1)
        inv = (1 - t) / z_bg + t / z_near  # linear in inverse depth, as a plane projects
        depth = np.repeat((1 / inv)[:, None], size, axis=1).astype(np.float32)
        ground = texture(rng, size, split) * gain * rng.uniform(0.5, 1.0)
        scene = np.where((rows >= horizon)[None, :, None], ground, scene)
    objects = sorted(rng.uniform(near, far, int(rng.integers(2, 7))), reverse=True)
    for z in objects:
        m = _shape_mask(rng, size)
        m &= depth >= z  # an object in front of the ground only
        depth[m] = z
        scene = np.where(m[None], texture(rng, size, split) * gain * rng.uniform(0.5, 1.0), scene)
    return scene.astype(np.float32), depth


CONTENT_COMPONENTS = ("splits", "reflectances", "lights")  # which content each split holds; the other components
# say how that content is made into scenes and captures


def split_components(task: str) -> dict[str, str]:
    """SHA-256 of each thing that makes ``task``'s scenes and the fabricated parts they are captured through:
    ``splits`` — which photographs, scene seeds and part seeds each split takes (``IMAGES``, ``SPLIT_SEEDS``,
    ``CONTENT``, ``PART_SEEDS``); ``photographs`` — their pixels as the scenes use them (as the installed
    scikit-image reads its files); ``generator`` — the source of the modules that draw the scenes (this one, and
    ``spectra`` and ``bands`` for hyperspectral); ``parts`` — the source of the subpackages that compute a fabricated part
    (``PART_MODEL``) and the shipped tolerance budget the parts are drawn from; for hyperspectral also
    ``reflectances`` (each split's measured reflectances, to 1e-6) and ``lights`` (the held-out lights, to 1e-6,
    and the bytes of the illuminant library ``illuminants.csv``)."""
    from doefab.io import sources_sha256

    # the generated splits' definition (the measured set's content is its files, none of it in training)
    names = {"images": IMAGES, "seeds": {s: SPLIT_SEEDS[s] for s in SYNTHETIC},
             "content": {s: CONTENT[s] for s in SYNTHETIC}, "part_seeds": {s: PART_SEEDS[s] for s in SYNTHETIC}}
    photos = hashlib.sha256()
    for pool in IMAGES:
        for name, a in zip(IMAGES[pool], _images(pool)):
            photos.update(f"{pool}/{name}{a.shape}".encode() + a.tobytes())
    sources = [Path(__file__)]
    out = {"splits": _sha(json.dumps(names, sort_keys=True).encode()), "photographs": photos.hexdigest(),
           "parts": _sha(sources_sha256(_PACKAGE, PART_MODEL).encode(),
                         (_PACKAGE / "tolerance" / "budget.toml").read_bytes())}
    if has(task, "spectral"):
        from doefab.reconstruction import bands, spectra
        from doefab.reconstruction.illuminant import LIBRARY_PATH

        sources += [Path(spectra.__file__), Path(bands.__file__)]
        out["reflectances"] = _sha(*(np.round(spectra.reflectances(s), 6).tobytes() for s in IMAGES))
        out["lights"] = _sha(np.round(spectra.val_lights(), 6).tobytes(), np.round(spectra.test_lights(), 6).tobytes(),
                             LIBRARY_PATH.read_bytes())
    out["generator"] = _sha(*(f.read_bytes() for f in sources))
    return out


def split_digest(task: str, components: dict | None = None) -> str:
    """SHA-256 of ``split_components`` (given, or computed): a network's weights record it and the components, so
    an evaluation can tell when the networks were trained on another split definition (the test scenes may then
    hold their training content) or on the same content made by other code or files."""
    return _sha(json.dumps(components or split_components(task), sort_keys=True).encode())


def split_digest_v1(task: str) -> str:
    """The digest weights recorded before ``split_components``: the photographs' names and the seeds of the
    train, val and test splits, and for hyperspectral each split's measured reflectances and the held-out lights
    (to 1e-6)."""
    seeds = {s: SPLIT_SEEDS[s] for s in ("train", "val", "test")}
    h = hashlib.sha256(json.dumps({"images": IMAGES, "seeds": seeds}, sort_keys=True).encode())
    if has(task, "spectral"):
        from doefab.reconstruction import spectra

        for arr in [spectra.reflectances(s) for s in ("train", "val", "test")] + [spectra.val_lights(),
                                                                                spectra.test_lights()]:
            h.update(np.round(np.asarray(arr, np.float64), 6).tobytes())
    return h.hexdigest()


def _sha(*chunks: bytes) -> str:
    h = hashlib.sha256()
    for c in chunks:
        h.update(c)
    return h.hexdigest()


def real_components() -> dict[str, str]:
    """SHA-256 of what makes the measured set's scenes (split ``real``, ``realdata``): its seeds and content pool,
    ``realdata``'s source, its HDR file, the depth scenes' names, images and depths (the Motorcycle as scikit-image
    reads it), and the displays' primaries (to 1e-6); ``metrics.json`` of a ``real`` evaluation records them."""
    from doefab.reconstruction import realdata

    names = json.dumps({"seed": SPLIT_SEEDS["real"], "part_seed": PART_SEEDS["real"], "content": CONTENT["real"]})
    return {"definition": _sha(names.encode(), Path(realdata.__file__).read_bytes()), "hdr": realdata.HDR_SHA256,
            "depth": _sha(*(b for name, img, depth, known in realdata.depth_scenes()
                            for b in (name.encode(), img.tobytes(), depth.tobytes(), known.tobytes()))),
            "light": _sha(*(np.round(v, 6).tobytes() for v in realdata.real_lights().values()))}

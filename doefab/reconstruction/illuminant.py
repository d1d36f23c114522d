"""The scene's illuminant from the grating's dispersion: a search the uncoded capture alone cannot make.

An RGB capture cannot tell illuminants apart that give the same colours (a spiky fluorescent lamp and a smooth
one of the same white point), yet the illuminant decides most of a scene's spectra: on our test scenes the
smooth least-squares inverse of the uncoded capture reaches about 12 dB PSNR, the same inverse told the
illuminant about 22 dB. The coded half disperses every band to its own offset, so each illuminant predicts a
different coded capture. For every illuminant ``e_j`` of a library the spectra are estimated from the uncoded
capture, ``s_j = N_j u`` with ``N_j = diag(e_j) (A_jᵀA_j + μ D²ᵀD² + εI)⁻¹ A_jᵀ``, ``A_j = ½ T diag(e_j)``
(reflectance smooth along wavelength), rendered through the coded PSFs, ``ĉ_j = Σ_λ T_λ p_λ ∗ s_jλ``, and
compared with the measured coded capture (unclipped pixels); the best ``N_j`` is the spectral estimate.

Rendering is linear in the capture: with ``Y_{λk} = p_λ ∗ u_k`` (31 × 3 convolutions, once per image) every
candidate is a 3 × 93 matrix product, so the search over the library costs little more than one rendering.
The library is colour-science's measured illuminants (CIE standard illuminants and light sources), shipped as
``doefab/weights/illuminants.csv`` (names and spectra, written from colour-science 0.4.7 by
:func:`write_illuminant_library`): the shipped network's candidates must not change when a colour-science
release adds, drops or renames an illuminant.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from doefab.errors import DoefabError
from doefab.imaging.captures import convolve_valid

__all__ = ["illuminant_library", "illuminant_names", "illuminant_inverses", "search_illuminant", "write_illuminant_library",
           "LIBRARY_PATH", "candidate_predictions", "mix_illuminants"]

LIBRARY_PATH = Path(__file__).resolve().parents[1] / "weights" / "illuminants.csv"


def write_illuminant_library(path: str | Path = LIBRARY_PATH) -> Path:
    """Write the installed colour-science's illuminants (``bands.illuminant_spectra``) as the shipped library
    (``name,400nm,...,700nm``)."""
    import csv
    import io

    from doefab.io import atomic_write_text
    from doefab.reconstruction.bands import HS_WAVELENGTHS_M, illuminant_spectra

    names, spectra = illuminant_spectra()
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["name", *(f"{round(lam * 1e9)}nm" for lam in HS_WAVELENGTHS_M)])
    w.writerows([n, *(f"{v:.10g}" for v in e)] for n, e in zip(names, spectra))
    atomic_write_text(Path(path), buf.getvalue())
    return Path(path)


@functools.lru_cache(maxsize=None)
def _read_library(path: str) -> tuple[tuple[str, ...], np.ndarray]:
    import csv

    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
        names = tuple(r[0] for r in rows[1:])
        spectra = np.array([[float(v) for v in r[1:]] for r in rows[1:]], np.float64)
    except (OSError, ValueError, IndexError) as exc:
        raise DoefabError(f"cannot read the illuminant library {path}: {exc}; restore it from the package "
                          "(git checkout doefab/weights/illuminants.csv) or rewrite it with "
                          "doefab.reconstruction.illuminant.write_illuminant_library()") from None
    from doefab.reconstruction.bands import HS_WAVELENGTHS_M

    bands = len(HS_WAVELENGTHS_M)
    if spectra.ndim != 2 or spectra.shape[1] != bands or not np.all(np.isfinite(spectra)):
        raise DoefabError(f"the illuminant library {path} must hold {bands} finite values (400–700 nm) per row")
    return names, spectra


def illuminant_library(path: str | Path = LIBRARY_PATH) -> np.ndarray:
    """[J, 31] measured illuminants on 400–700 nm (10 nm), each normalised to peak 1: the shipped library."""
    return _read_library(str(path))[1].copy()


def illuminant_names(path: str | Path = LIBRARY_PATH) -> tuple[str, ...]:
    """The shipped library's illuminant names, in the order of ``illuminant_library``'s rows (e.g. "D65")."""
    return _read_library(str(path))[0]


def illuminant_inverses(response: np.ndarray, library: np.ndarray, smooth: float = 1e-3,
                        eps: float = 1e-6) -> np.ndarray:
    """[J, C, 3] smooth least-squares inverses of a half-exposure capture, one per illuminant:
    ``N_j = diag(e_j) argmin_ρ ‖½ T diag(e_j) ρ − c‖² + μ‖D² ρ‖²`` (ρ the reflectance, D² second differences)."""
    t = 0.5 * np.asarray(response, np.float64)
    lib = np.asarray(library, np.float64)
    if t.ndim != 2 or t.shape[0] != 3 or lib.ndim != 2 or lib.shape[1] != t.shape[1]:
        raise DoefabError(f"response must be [3, C] and the library [J, C], got {t.shape} and {lib.shape}")
    n = t.shape[1]
    d2 = np.diff(np.eye(n), 2, axis=0)
    out = []
    for e in lib:
        a = t * e[None, :]
        out.append(e[:, None] * np.linalg.solve(a.T @ a + smooth * d2.T @ d2 + eps * np.eye(n), a.T))
    return np.stack(out)


def candidate_predictions(coded: torch.Tensor, uncoded: torch.Tensor, psf_coded: torch.Tensor,
                          response: torch.Tensor, inverses: torch.Tensor, clipped: float = 0.98,
                          max_side: int = 256) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(pred [B, J, 3, P], target [B, 3, P], valid [B, 3, P]): the coded capture each candidate illuminant
    predicts from ``uncoded`` (P pixels of the central ``max_side``² at most), the measured one and its unclipped
    pixels.

    Args:
        coded, uncoded: [B, 3, H, W] captures.  psf_coded: [C, K, K] coded PSF per band.
        response: [3, C] sensor response.  inverses: [J, C, 3] from :func:`illuminant_inverses`.
        max_side: larger captures are searched on their central ``max_side``² pixels (the illuminant is one
            per scene; this keeps a 512² reconstruction within its time budget).
    """
    if coded.ndim != 4 or coded.shape != uncoded.shape or coded.shape[1] != 3:
        raise DoefabError(f"captures must be two [B, 3, H, W] tensors, got {tuple(coded.shape)}, {tuple(uncoded.shape)}")
    c_bands = psf_coded.shape[0]
    if response.shape != (3, c_bands) or inverses.shape[1:] != (c_bands, 3):
        raise DoefabError(f"response [3, {c_bands}] and inverses [J, {c_bands}, 3] needed, got "
                          f"{tuple(response.shape)} and {tuple(inverses.shape)}")
    with torch.no_grad():
        b, _, h, w = coded.shape
        if h > max_side or w > max_side:
            y0, x0 = max(0, (h - max_side) // 2), max(0, (w - max_side) // 2)
            coded = coded[..., y0:y0 + max_side, x0:x0 + max_side]
            uncoded = uncoded[..., y0:y0 + max_side, x0:x0 + max_side]
            b, _, h, w = coded.shape
        k = psf_coded.shape[-1]  # (k - 1) // 2 before, k // 2 after: the frame centred as convolve's 'same'
        u = F.pad(uncoded.float(), ((k - 1) // 2, k // 2) * 2, mode="replicate")  # light from just outside
        y = convolve_valid(u[:, None], psf_coded.float()[:, None])  # [B, C, 3, H, W]: Y_{λk} = p_λ ∗ u_k
        y = y.reshape(b, c_bands * 3, h * w)
        # candidate j predicts coded channel r as Σ_{λ,k} T[r,λ] N_j[λ,k] Y_{λk}
        wts = torch.einsum("rl,jlk->jrlk", response.float(), inverses.float()).reshape(-1, c_bands * 3)
        pred = torch.einsum("mq,bqp->bmp", wts, y).reshape(b, -1, 3, h * w)  # [B, J, 3, HW]
        target = coded.float().reshape(b, 3, h * w)
        valid = (target < clipped).float()
    return pred, target, valid


def search_illuminant(coded: torch.Tensor, uncoded: torch.Tensor, psf_coded: torch.Tensor, response: torch.Tensor,
                      inverses: torch.Tensor, clipped: float = 0.98,
                      max_side: int = 256) -> tuple[torch.Tensor, torch.Tensor]:
    """(index [B], cost [B, J]) of the illuminant whose spectra, estimated from ``uncoded``, best predict
    ``coded`` (arguments as :func:`candidate_predictions`)."""
    pred, target, valid = candidate_predictions(coded, uncoded, psf_coded, response, inverses, clipped, max_side)
    v = valid[:, None]
    cost = (((pred - target[:, None]) ** 2) * v).sum(dim=(-2, -1)) / v.sum(dim=(-2, -1)).clamp_min(1.0)
    return cost.argmin(dim=1), cost


def mix_illuminants(coded: torch.Tensor, uncoded: torch.Tensor, psf_coded: torch.Tensor, response: torch.Tensor,
                    inverses: torch.Tensor, clipped: float = 0.98, max_side: int = 256) -> torch.Tensor:
    """[B, J] non-negative weights of the candidates' estimates whose mixture best predicts ``coded``
    (least squares on the unclipped pixels): light that is no single candidate is met by a blend of them, and
    light that is one of them gets (nearly) all the weight. The mixed inverse is ``Σ_j w_j N_j``."""
    from scipy.optimize import nnls

    pred, target, valid = candidate_predictions(coded, uncoded, psf_coded, response, inverses, clipped, max_side)
    out = []
    for p, t, v in zip(pred, target, valid):
        j = p.shape[0]
        # [Aᵀ b] column-major as LAPACK takes it: the rows of m, in float64 (a float32 value times a 0/1 mask is exact)
        m = torch.empty(j + 1, t.numel(), dtype=torch.float64, device=p.device)
        m[:j] = (p * v).reshape(j, -1)
        m[j] = (t * v).reshape(-1)
        w = None
        # a black or wholly clipped capture says nothing, nor one with NaN in it: below
        if not bool(m.isnan().any()) and bool(m[:j].any()) and bool(m[j].any()):
            # NNLS on a QR factor of Aᵀ (not the Gram matrix: candidates are nearly collinear, cond(AᵀA) ~ 1e16).
            # [Aᵀ b] = Q'R' gives Aᵀ's R in R'[:J, :J] and Qᵀb in R'[:J, J], with no Q formed:
            # min ‖Aᵀw − b‖ = min ‖Rw − Qᵀb‖ up to a constant
            r = torch.linalg.qr(m.T, mode="r")[1]
            w, _ = nnls(r[:j, :j].cpu().numpy(), r[:j, j].cpu().numpy())  # scipy's solver, on the CPU
            w = w if np.isfinite(w).all() and w.sum() > 0 else None
        if w is None:  # the single best member (or the first, when nothing can be told apart)
            p, t, v = p.double(), t.double(), v.double()
            cost = (((p - t[None]) ** 2) * v[None]).sum(dim=(-2, -1))
            w = np.zeros(p.shape[0])
            w[int(cost.argmin())] = 1.0
        out.append(torch.from_numpy(np.asarray(w, np.float64)))
    return torch.stack(out).float().to(coded.device)

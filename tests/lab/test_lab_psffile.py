"""psf_pair.npz: a PSFPair written and read back bit for bit, and every corrupt file refused with its problem."""

import io
import json

import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError
from doefab.optics.psf import PSFPair
from doefab.optics.psffile import save_psf_pair


def _pair(d=2, w=3, k=7, seed=0):
    rng = np.random.default_rng(seed)
    c = torch.from_numpy(rng.random((d, w, k, k)).astype(np.float32) / k**2)
    u = torch.from_numpy(rng.random((d, w, k, k)).astype(np.float32) / k**2)
    return doefab.PSFPair(c, u, (656e-9, 589e-9, 486e-9)[:w], (float("inf"), 2.0)[:d], 5.4e-6)


def test_round_trip_is_bit_exact_with_provenance(tmp_path):
    pair = _pair()
    prov = {"source": "calibrate", "levels_sha256": "ab" * 32, "shifts_px": [[0.25, -1.5]]}
    path = pair.save(tmp_path / "psf_pair.npz", provenance=prov)
    back = doefab.PSFPair.load(path)
    assert back.coded.dtype == torch.float32 and back.uncoded.dtype == torch.float32
    assert back.coded.numpy().tobytes() == pair.coded.numpy().tobytes()
    assert back.uncoded.numpy().tobytes() == pair.uncoded.numpy().tobytes()
    assert back.wavelengths == pair.wavelengths and back.depths == pair.depths  # inf survives
    assert back.sensor_pitch == pair.sensor_pitch and back.camera is None
    assert back.provenance == prov
    # the documented layout: plain numpy, no pickles
    with np.load(path, allow_pickle=False) as z:
        assert str(z["format"]) == "doefab-psf-pair" and int(z["version"]) == 1
        assert z["coded"].shape == (2, 3, 7, 7) and z["depths_m"].dtype == np.float64
        assert json.loads(str(z["provenance"])) == prov
    # a pair read back saves its own provenance again
    again = back.save(tmp_path / "again.npz")
    assert PSFPair.load(again).provenance == prov


def _rewrite(src, dst, **changes):
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    dst.write_bytes(buf.getvalue())
    return dst


@pytest.mark.parametrize("change, needle", [
    ({"version": np.array(2)}, "version 2"),
    ({"format": np.array("something-else")}, "format"),
    ({"uncoded": None}, "lacks the keys ['uncoded']"),
    ({"provenance": None}, "lacks the keys ['provenance']"),
    ({"wavelengths_m": np.array([550e-9])}, "wavelengths_m has shape (1,)"),
    ({"sensor_pitch_m": np.array(5.4)}, "sensor_pitch_m"),
    ({"provenance": np.array("[1, 2]")}, "provenance is not a JSON object"),
])
def test_corrupt_files_are_refused_naming_the_problem(tmp_path, change, needle):
    good = _pair().save(tmp_path / "good.npz")
    bad = _rewrite(good, tmp_path / "bad.npz", **change)
    with pytest.raises(DoefabError) as exc:
        doefab.PSFPair.load(bad)
    assert needle in str(exc.value) and str(bad) in str(exc.value)


def test_nan_and_negative_psfs_are_refused_on_load_and_on_save(tmp_path):
    good = _pair().save(tmp_path / "good.npz")
    with np.load(good) as z:
        coded = z["coded"].copy()
    coded[0, 0, 3, 3] = np.nan
    with pytest.raises(DoefabError, match="coded holds 1 NaN"):
        PSFPair.load(_rewrite(good, tmp_path / "nan.npz", coded=coded))
    coded[0, 0, 3, 3] = -0.5
    with pytest.raises(DoefabError, match="negative"):
        PSFPair.load(_rewrite(good, tmp_path / "neg.npz", coded=coded))
    pair = _pair()
    pair.uncoded[0, 0, 0, 0] = float("nan")
    with pytest.raises(DoefabError, match="uncoded holds 1 NaN"):
        save_psf_pair(pair, tmp_path / "never.npz")
    half = _pair()
    half.uncoded = None
    with pytest.raises(DoefabError, match="uncoded PSF is missing"):
        half.save(tmp_path / "never.npz")
    with pytest.raises(DoefabError, match="JSON"):
        _pair().save(tmp_path / "never.npz", provenance={"x": float("nan")})
    assert not (tmp_path / "never.npz").exists()


def test_a_pickle_or_foreign_file_is_refused(tmp_path):
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(DoefabError, match="not a readable .npz"):
        PSFPair.load(tmp_path / "junk.npz")
    with pytest.raises(DoefabError, match="not found"):
        PSFPair.load(tmp_path / "missing.npz")


def test_the_two_calibration_files_given_the_wrong_way_round_are_told_apart(tmp_path):
    from doefab.imaging.crosstalk import save_crosstalk

    w = 8
    cross = save_crosstalk(tmp_path / "crosstalk.json", np.full(w, 0.05), np.full(w, 0.04), np.full(w, 1e-3),
                           np.full(w, 1e-3))
    np.savez(tmp_path / "psf_pair.npz", coded=np.zeros((1, 1, 3, 3)))
    with pytest.raises(DoefabError, match=r"crosstalk\.json is a JSON file, not a PSF pair .*goes to --crosstalk"):
        PSFPair.load(cross)
    with pytest.raises(DoefabError, match=r"psf_pair\.npz is a numpy archive, not a crosstalk file .*goes to --psf"):
        doefab.DualPixelCrosstalk.load(tmp_path / "psf_pair.npz")

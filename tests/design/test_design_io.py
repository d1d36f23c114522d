import json

import numpy as np
import pytest

import doefab
from doefab.design.design import levels_sha256
from doefab.errors import DoefabError
from doefab.fabrication.levels import level_step, quantize_levels


@pytest.fixture(scope="module")
def design(tiny_camera, tiny_streak):
    return doefab.optimize("streak", iterations=3, camera=tiny_camera, progress=False, task_params=tiny_streak)


def test_quantization_rounds_to_nearest_and_is_idempotent(tiny_camera):
    d = level_step(tiny_camera)
    h = np.array([[0.0, 0.49 * d, 0.51 * d, 7.5 * d + 1e-12, 15.49 * d, 15.51 * d]])
    assert quantize_levels(h, tiny_camera).tolist() == [[0, 0, 1, 8, 15, 0]]  # nearest; 16 wraps to 0
    rng = np.random.default_rng(0)
    h = rng.uniform(-3e-6, 3e-6, (40, 40))
    q = doefab.quantize_height(h, tiny_camera)
    assert np.array_equal(doefab.quantize_height(q, tiny_camera), q)
    assert np.abs(((h - q) / d + 8) % 16 - 8).max() <= 0.5 + 1e-9  # within half a level (mod 16)


def test_design_and_mask_quantization_are_the_same_rule(tiny_camera):
    import torch

    from doefab.fabrication.levels import levels_to_height, quantize_torch

    h = np.random.default_rng(1).uniform(-5e-6, 5e-6, (64, 64))
    via_torch = quantize_torch(torch.from_numpy(h), tiny_camera).numpy()
    via_masks = levels_to_height(quantize_levels(h, tiny_camera), tiny_camera)
    assert np.allclose(via_torch, via_masks, rtol=0, atol=1e-15)


def test_save_load_round_trip(design, tmp_path):
    design.save(tmp_path)
    meta = json.loads((tmp_path / "design.json").read_text())
    for key in ("task", "camera", "wavelengths_m", "depths_m", "metrics", "seed", "levels_sha256", "versions"):
        assert key in meta
    assert {"continuous", "quantized"} <= set(meta["metrics"])
    assert meta["levels_sha256"] == levels_sha256(design.levels)
    back = doefab.Design.load(tmp_path)
    assert np.array_equal(back.levels, design.levels) and back.levels.dtype == np.uint8
    assert np.array_equal(back.height, design.height)
    assert back.camera == design.camera and back.metrics == design.metrics
    # the levels are exactly the quantization of what was saved (idempotent through the file)
    assert np.array_equal(quantize_levels(back.quantized_height, back.camera), back.levels)
    for f in ("levels.png", "history.csv", "psf_target_vs_design.png"):
        assert (tmp_path / f).stat().st_size > 0


def test_corrupt_design_folders_refused(design, tmp_path):
    design.save(tmp_path)
    lv = np.load(tmp_path / "levels.npy")
    lv[0, 0] ^= 1
    np.save(tmp_path / "levels.npy", lv)
    with pytest.raises(DoefabError, match="does not match levels_sha256"):
        doefab.Design.load(tmp_path)
    np.save(tmp_path / "levels.npy", lv.astype(np.int32))
    with pytest.raises(DoefabError, match="dtype int32"):
        doefab.Design.load(tmp_path)
    np.save(tmp_path / "levels.npy", np.zeros((5, 5), np.uint8))
    with pytest.raises(DoefabError, match="shape"):
        doefab.Design.load(tmp_path)
    (tmp_path / "levels.npy").write_bytes(b"garbage")
    with pytest.raises(DoefabError, match="not a readable"):
        doefab.Design.load(tmp_path)
    (tmp_path / "design.json").write_text("{")
    with pytest.raises(DoefabError, match="not valid JSON"):
        doefab.Design.load(tmp_path)
    with pytest.raises(DoefabError, match="design.json is missing"):
        doefab.Design.load(tmp_path / "nowhere")


def test_nan_height_in_design_refused(design, tmp_path):
    design.save(tmp_path)
    h = np.load(tmp_path / "height.npy")
    h[1, 1] = np.nan
    np.save(tmp_path / "height.npy", h)
    with pytest.raises(DoefabError, match="finite"):
        doefab.Design.load(tmp_path)

"""crosstalk.json: per-column ratios and standard errors written, read back as the calibrated camera, and refused
when corrupt."""

import json

import numpy as np
import pytest

import doefab
from doefab.errors import DoefabError
from doefab.imaging.crosstalk import save_crosstalk


def _profiles(w=16):
    x = np.linspace(-1, 1, w)
    return 0.05 + 0.01 * x, 0.04 - 0.01 * x, np.full(w, 1e-4), np.full(w, 2e-4)


def test_round_trip_gives_the_camera_as_calibrated(tmp_path):
    a, b, sa, sb = _profiles()
    path = save_crosstalk(tmp_path / "crosstalk.json", a, b, sa, sb, {"recordings_sha256": "cd" * 32})
    rec = json.loads(path.read_text())
    assert rec["format"] == "doefab-crosstalk" and rec["version"] == 1 and rec["columns"] == 16
    assert rec["recordings_sha256"] == "cd" * 32
    cam = doefab.DualPixelCrosstalk.load(path)
    np.testing.assert_array_equal(cam.alpha_lr, a)  # JSON floats round-trip exactly
    np.testing.assert_array_equal(cam.alpha_rl, b)
    np.testing.assert_array_equal(cam.estimate[0], a)
    np.testing.assert_array_equal(cam.estimate[1], b)
    np.testing.assert_array_equal(cam.standard_error[0], sa)
    # the camera unmixes a pair mixed by these ratios exactly
    rng = np.random.default_rng(0)
    left, right = rng.random((4, 16)), rng.random((4, 16))
    mixed = doefab.mix_crosstalk(left, right, a, b)
    out_l, out_r = doefab.unmix_crosstalk(*mixed, *cam.estimate)
    np.testing.assert_allclose(out_l, left, atol=1e-12)
    np.testing.assert_allclose(out_r, right, atol=1e-12)


@pytest.mark.parametrize("edit, needle", [
    (lambda r: r.update(version=2), "version 2"),
    (lambda r: r.update(format="other"), "not a doefab-crosstalk file"),
    (lambda r: r.pop("alpha_rl_se"), "lacks the keys ['alpha_rl_se']"),
    (lambda r: r.update(alpha_rl=r["alpha_rl"][:-1]), "of one length"),
    (lambda r: r.update(columns=3), "columns is 3"),
    (lambda r: r.update(alpha_lr=[0.6] * 16, alpha_rl=[0.5] * 16), "no dual-pixel crosstalk"),
    (lambda r: r.update(alpha_lr_se=[-1.0] * 16), "standard errors"),
])
def test_corrupt_files_are_refused(tmp_path, edit, needle):
    path = save_crosstalk(tmp_path / "crosstalk.json", *_profiles(), {})
    rec = json.loads(path.read_text())
    edit(rec)
    path.write_text(json.dumps(rec))
    with pytest.raises(DoefabError) as exc:
        doefab.DualPixelCrosstalk.load(path)
    assert needle in str(exc.value) and str(path) in str(exc.value)


def test_save_refuses_before_writing(tmp_path):
    a, b, sa, sb = _profiles()
    with pytest.raises(DoefabError, match="may not set"):
        save_crosstalk(tmp_path / "x.json", a, b, sa, sb, {"alpha_lr": 1})
    with pytest.raises(DoefabError, match="of one length"):
        save_crosstalk(tmp_path / "x.json", a, b[:3], sa, sb)
    assert not (tmp_path / "x.json").exists()
    with pytest.raises(DoefabError, match="not found"):
        doefab.DualPixelCrosstalk.load(tmp_path / "x.json")

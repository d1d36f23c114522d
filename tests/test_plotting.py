"""Figures (``doefab.plotting``): infinity labelled, one shared scale, design PSF panels on a log scale."""

import numpy as np


def test_figures_label_infinity_and_share_one_scale(tmp_path):
    from doefab.plotting import depth_label, psf_pair_figure

    assert depth_label(float("inf")) == "z = ∞" and depth_label(2.0) == "z = 2 m"
    c = np.zeros((1, 1, 63, 63))
    c[0, 0, 31, 31] = 0.5
    u = c * 0.1
    psf_pair_figure(tmp_path / "f.png", c, u, [float("inf")], 5.4e-6)
    assert (tmp_path / "f.png").stat().st_size > 1000


def test_design_psf_panels_are_drawn_on_a_log_scale(tmp_path, monkeypatch):
    from types import SimpleNamespace

    import doefab.plotting
    from doefab.plotting import design_psf_figure

    seen = {}
    monkeypatch.setattr(doefab.plotting, "plot_psf_grid", lambda path, panels, pitch, **kw: seen.update(kw))
    d = SimpleNamespace(wavelengths=[5e-7, 6e-7], depths=[5.0], camera=SimpleNamespace(sensor_pitch=5.4e-6),
                        task="grating", n_levels=16)
    psf = np.zeros((1, 2, 15, 15))
    psf[0, :, 7, 7] = 1.0
    design_psf_figure(tmp_path / "f.png", d, psf, psf)
    assert seen["log"] is True and "log scale" in seen["suptitle"]

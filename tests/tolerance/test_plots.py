"""The tolerance figures keep every label inside the saved image (issue 37: the tornado's x label was cut off)."""

import pytest
from matplotlib.figure import Figure
from matplotlib.text import Text

from doefab.tolerance import plots
from doefab.tolerance.reporttext import REMEDY


@pytest.fixture
def saved(monkeypatch):
    """Per figure saved during the test, the texts that fall outside the region of it the file holds."""
    out, save = [], Figure.savefig

    def record(self, fname, *args, **kwargs):
        renderer = self.canvas.get_renderer()
        self.draw(renderer)
        tight = kwargs.get("bbox_inches") == "tight"
        region = self.get_tightbbox(renderer).transformed(self.dpi_scale_trans) if tight else self.bbox
        out.append(_outside(self, region, renderer))
        return save(self, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", record)
    return out


def _drawn_texts(fig) -> list[Text]:
    """The texts a saved figure shows: every label, title, legend and annotation, and the tick labels inside
    each axis's view (matplotlib keeps a few beyond it that it does not draw)."""
    ticks, shown = set(), []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                ticks.update((id(tick.label1), id(tick.label2)))
                if lo - 1e-9 * abs(hi - lo) <= tick.get_loc() <= hi + 1e-9 * abs(hi - lo):
                    shown += [t for t in (tick.label1, tick.label2) if t.get_visible()]
    return shown + [t for t in fig.findobj(Text) if id(t) not in ticks and t.get_visible()]


def _outside(fig, region, renderer) -> list[str]:
    bad = []
    for t in _drawn_texts(fig):
        if not t.get_text().strip():
            continue
        e = t.get_window_extent(renderer)
        if e.x0 < region.x0 - 1 or e.x1 > region.x1 + 1 or e.y0 < region.y0 - 1 or e.y1 > region.y1 + 1:
            bad.append(t.get_text())
    return bad


def test_every_label_of_the_tolerance_figures_is_inside_the_image(tmp_path, saved):
    rows = [{"error": name, "value": 0.5, "unit": "µm", "delta": -0.01 * i} for i, name in enumerate(REMEDY)]
    plots.tornado_plot(tmp_path / "tornado.png", rows, 0.869)
    plots.yield_plot(tmp_path / "yield.png", [True, False, True, True], "PSF metric ≥ 0.800, highlight PSNR ≥ 28 dB")
    plots.levels_plot(tmp_path / "levels.png", [{"levels": n, "metric": 0.8, "worst": 0.7} for n in (16, 8, 4, 2)])
    plots.distribution_plot(tmp_path / "d.png", {"nominal_psf": [29.0, 29.5, 30.1]}, "dB",
                            "delivered highlight PSNR", 28.0, 29.9)
    assert saved == [[]] * 4

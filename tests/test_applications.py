"""The application registry: one row per application, and the layers that look it up agree with it."""

import numpy as np
import pytest

from doefab.applications import APPLICATIONS, application, of_design
from doefab.errors import DoefabError


def test_an_unknown_application_is_one_error_naming_the_choices():
    with pytest.raises(DoefabError, match="hdr, hyperspectral, depth"):
        application("polarization")
    assert of_design("no-such-design") is None


@pytest.mark.parametrize("name", list(APPLICATIONS))
def test_each_application_is_served_by_a_design_task_and_judged_by_a_metric_it_reports(name):
    """Its design task is one doefab.tasks builds, and maps back to it; its primary metric is one the task's
    metrics return on a reconstruction, with the direction the tolerance study's delivered table gives it; a
    reconstruction worse by that metric's direction scores worse."""
    from doefab.reconstruction.metrics import metrics_for
    from doefab.tasks import TASKS
    from doefab.tolerance.spec import DELIVERED

    from doefab.optics.camera import PRESETS

    app = application(name)
    assert app.design_task in TASKS and of_design(app.design_task) is app
    assert app.camera_preset in PRESETS
    rng = np.random.default_rng(0)
    if name == "depth":
        target = rng.uniform(1, 5, (32, 32))
        near, far = target * 1.02, target * 1.4
    else:
        shape = (3 if name == "hdr" else 31, 32, 32)
        target = rng.uniform(0, 4 if name == "hdr" else 1, shape)
        target[:, :4, :4] = 100.0 if name == "hdr" else target[:, :4, :4]  # a highlight for the HDR metrics
        near, far = target + rng.normal(0, 0.01, shape), target + rng.normal(0, 0.5, shape)
    good, bad = metrics_for(name, near, target), metrics_for(name, far, target)
    m = app.primary_metric
    assert m in good and (DELIVERED[name][m][1] == "+") == app.higher_is_better
    assert (good[m] > bad[m]) == app.higher_is_better
    # every registry row is a metric the function returns, and each one's direction is what it measures: the
    # near reconstruction scores better than the far one by it, and lies within the metric's span
    assert sorted(good) == sorted(r.name for r in app.metrics)
    for r in app.metrics:
        assert (good[r.name] > bad[r.name]) == r.higher_is_better, r.name
        assert r.span[0] <= good[r.name] <= r.span[1], r.name


def test_the_tables_that_were_copies_are_the_registry():
    """The four application ↔ design tables that had to agree (scene, tolerance spec, network judge,
    reconstruction specs) and the tolerance study's primary metric equal the registry's rows."""
    from doefab.pipeline.scene import TASK_DESIGN
    from doefab.reconstruction.specs import SPECS
    from doefab.tolerance.netjudge import RECON_TASK
    from doefab.tolerance.spec import PRIMARY, TASK_OF_DESIGN

    rows = {n: a.design_task for n, a in APPLICATIONS.items()}
    assert rows == {"hdr": "streak", "hyperspectral": "grating", "depth": "half-ring"}  # the paper's pairing
    # the paper's headline metric of each table: highlight PSNR (Table 1), PSNR (Table 2), MAE (Table 3)
    assert {n: (a.primary_metric, a.primary_unit) for n, a in APPLICATIONS.items()} == {
        "hdr": ("psnr_highlight", "dB"), "hyperspectral": ("psnr", "dB"), "depth": ("mae", "m")}
    assert TASK_DESIGN == rows == {n: s.design for n, s in SPECS.items()}
    assert TASK_OF_DESIGN == RECON_TASK == {d: n for n, d in rows.items()}
    assert PRIMARY == {n: a.primary_metric for n, a in APPLICATIONS.items()}


def test_the_metric_and_reconstruction_tables_are_views_of_the_registry(monkeypatch):
    """The reports' metric names and units, the tolerance spec's directions and spans, the reconstruction specs
    and the design ↔ application tables are read from the registry's rows on every lookup: a row changed or
    added there shows in each of them at once."""
    import dataclasses

    import doefab.applications as apps
    from doefab.pipeline.scene import TASK_DESIGN
    from doefab.reconstruction.metrics import DISPLAY, metric_text
    from doefab.reconstruction.specs import SPECS, get_spec
    from doefab.tolerance.netjudge import RECON_TASK
    from doefab.tolerance.spec import DELIVERED, PRIMARY, SPAN, TASK_OF_DESIGN, limit_range

    assert DISPLAY["depth"]["mae"] == ("depth MAE", "m") and DELIVERED["hdr"]["psnr"] == ("db", "+")
    assert SPAN["hyperspectral"]["sam"] == (0.0, np.pi) and SPECS["depth"].crop == 128
    row = apps.APPLICATIONS["depth"]
    monkeypatch.setitem(apps.APPLICATIONS, "depth", dataclasses.replace(
        row, crop=160, metrics=(apps.Metric("mae", "MAE", "mm", False, (0.0, 9.0)),)))
    assert DISPLAY["depth"] == {"mae": ("MAE", "mm")} and DELIVERED["depth"] == {"mae": ("mm", "-")}
    assert SPAN["depth"] == {"mae": (0.0, 9.0)} and SPECS["depth"].crop == 160 == get_spec("depth").crop
    assert limit_range("depth", "mae_mm_max") == (0.0, 9.0, "mm") and metric_text("depth", "mae", 1.5) == "1.500 mm"
    monkeypatch.setitem(apps.APPLICATIONS, "toy", dataclasses.replace(row, name="toy", design_task="toy-task",
                                                                      primary_metric="mae"))
    assert TASK_DESIGN["toy"] == "toy-task" and TASK_OF_DESIGN["toy-task"] == RECON_TASK["toy-task"] == "toy"
    assert PRIMARY["toy"] == "mae" and "toy" in SPECS and len(SPECS) == len(apps.APPLICATIONS) == 4


@pytest.mark.parametrize("name", list(APPLICATIONS))
def test_each_property_is_what_the_design_task_and_metric_make_the_application(name):
    """``spectral``: its design task images more bands than the sensor's three colours; ``depth``: its design
    task works at more than one plane; ``highlights``: it is judged by highlight PSNR — each read from the task
    and the metric tables, not from the registry."""
    from doefab.applications import design_is, has
    from doefab.optics.camera import Camera
    from doefab.tasks import get_task

    app = application(name)
    task = get_task(app.design_task)
    cam = Camera.preset(app.camera_preset)
    task.bind(cam)
    assert has(name, "spectral") == app.spectral == (len(task.wavelengths(cam)) > 3)
    assert has(name, "depth") == app.depth == (len(task.depths(cam)) > 1)
    assert has(name, "highlights") == app.highlights == (app.primary_metric == "psnr_highlight")
    assert all(design_is(app.design_task, p) == has(name, p) for p in ("spectral", "depth", "highlights"))


def test_a_property_of_an_unknown_application_is_false_and_an_unknown_property_one_error():
    from doefab.applications import design_is, has

    assert not has("polarization", "spectral") and not design_is("no-such-design", "depth")
    with pytest.raises(DoefabError, match="spectral, depth, highlights"):
        has("hdr", "colour")
    with pytest.raises(DoefabError, match="spectral, depth, highlights"):
        design_is("no-such-design", "colour")

"""Extending doefab: a toy application (its registry row, its network module, its design task) and a toy source of
error (one row of ``tolerance.sources``), added in temporary registries, run through resolve → train one step →
tolerance one part judged through the toy's network."""

import dataclasses
import sys
import types

import numpy as np
import pytest
import torch

from doefab.errors import DoefabError


def _toy_network_module():
    """A network module as ``Application.network`` names one: ``default_arch``, ``build``, ``loss``. The toy
    network scales the uncoded capture by one learned gain."""
    mod = types.ModuleType("toy_network")

    class Gain(torch.nn.Module):
        def __init__(self, arch):
            super().__init__()
            self.gain = torch.nn.Parameter(torch.tensor(float(arch["gain"])))

        def forward(self, coded, uncoded, psf=None):
            return self.gain * uncoded

    mod.default_arch = lambda variant: {"gain": 0.5}
    mod.build = lambda variant, arch: Gain(arch)
    mod.loss = lambda pred, target: (pred - target).abs().mean()
    return mod


def _toy_source():
    """A fraction of the uncoded half's light (budget ``[toy] loss_percent``, every part) spread evenly over the
    PSF window: stray light that the toy network, which reads the uncoded capture, sees."""
    from doefab.tolerance import sources

    def psf(psfs, part):  # the halves judged (the PSF level judges the coded one alone)
        if "uncoded" not in psfs:
            return psfs
        loss = part.extra.get("uncoded_loss", 0.0)
        u = psfs["uncoded"]
        spread = u.sum(dim=(-2, -1), keepdim=True) / (u.shape[-1] * u.shape[-2])
        return {**psfs, "uncoded": u * (1 - loss) + loss * spread}

    return sources.Source("uncoded stray light", (sources.BudgetKey("toy", "loss_percent", 0, 100),),
                          fixed=lambda b: {"extra": {"uncoded_loss": sources.budget_value(b, "toy", "loss_percent")
                                                     / 100}},
                          psf=psf)


@pytest.fixture
def toy(grating_design, tmp_path, monkeypatch):
    """The toy application "toy" served by design task "toy-grating" (the grating task's physics under a new
    name), its design folder, and the committed-design lookup pointed at it."""
    import doefab.applications as apps
    import doefab.design.committed as committed
    from doefab.design.design import Design
    from doefab.tasks import TASKS
    from doefab.tasks.grating import GratingTask

    monkeypatch.setitem(sys.modules, "toy_network", _toy_network_module())
    monkeypatch.setitem(TASKS, "toy-grating", GratingTask)
    monkeypatch.setitem(apps.APPLICATIONS, "toy", dataclasses.replace(
        apps.APPLICATIONS["hdr"], name="toy", design_task="toy-grating", primary_metric="psnr",
        network="toy_network", highlights=False, kernel=31, crop=64, summary="a toy"))
    folder = tmp_path / "design"
    d = Design.load(grating_design(80, 31))
    # an RGB application's bands go red first, one per colour channel (``applications.band_problem``)
    dataclasses.replace(d, task="toy-grating", wavelengths=tuple(reversed(d.wavelengths)), psf_quantized=None,
                        targets=None).save(folder)
    monkeypatch.setattr(committed, "committed_dir", lambda name: folder)
    return folder


def test_a_toy_application_and_a_toy_error_source_run_through_resolve_train_and_tolerance(toy, tmp_path,
                                                                                          monkeypatch):
    from doefab.applications import application
    from doefab.pipeline.scene import load_scene
    from doefab.pipeline.system import resolve
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.train import train
    from doefab.tolerance import sources
    from doefab.tolerance.errors import PartErrors, load_budget
    from doefab.tolerance.montecarlo import monte_carlo
    from doefab.tolerance.netjudge import NetworkJudge
    from doefab.tolerance.study import judge_for

    # resolve: the toy's scene reaches its design task, and the task's physics checks apply to it
    scene = tmp_path / "toy.toml"
    scene.write_text('task = "toy"\nstages = ["design"]\n[camera]\npreset = "hdr"\n')
    with pytest.raises(DoefabError, match="kernel_px 31: the grating's first order lands"):
        resolve(load_scene(scene))
    scene.write_text('task = "toy"\nstages = ["design"]\n[camera]\npreset = "hdr"\n[optics]\nkernel_px = 311\n')
    got = resolve(load_scene(scene))
    assert got.settings["design_task"] == "toy-grating" and got.settings["kernel_px"] == 311

    # train one step: the toy network, its loss, its scenes and its metrics, from the registry
    rec = train("toy", "proposed", minutes=1, out_dir=tmp_path / "t", weights_dir=tmp_path / "w", design=toy,
                crop=64, val_images=1, val_every=100, progress=False, max_steps=1, batch=1)
    names = [m.name for m in application("toy").metrics]
    assert rec["task"] == "toy" and set(rec["validation"]) == {*names, "images", "crop_px"}
    net = load_reconstructor("toy", "proposed", tmp_path / "w", design=toy)
    assert float(net.model.gain.detach()) != 0.5  # one optimiser step moved the learned gain

    # tolerance one part: the toy source is one row; its budget key is checked and its effect judged
    budget_file = tmp_path / "budget.toml"
    budget_file.write_text("[toy]\nloss_percent = 30\n")
    with pytest.raises(DoefabError, match=r"unknown section \[toy\]"):
        load_budget(budget_file)
    monkeypatch.setattr(sources, "SOURCES", (*sources.SOURCES, _toy_source()))
    rows = monte_carlo(toy, load_budget(budget_file), 1, tmp_path / "mc", progress=False, workers=1,
                       networks={"images": 1, "size": 64}, weights_dir=tmp_path / "w")
    part = PartErrors(**rows[0]["errors"])
    assert part.extra == {"uncoded_loss": pytest.approx(0.3)} and sorted(rows[0]["network"]["nominal_psf"]) == \
        sorted(names)
    judge = NetworkJudge(judge_for(str(toy), 1), images=1, size=64, weights_dir=tmp_path / "w")
    again = judge.evaluate(part)["nominal_psf"]
    without = judge.evaluate(dataclasses.replace(part, extra={}))["nominal_psf"]
    assert again["psnr"] == pytest.approx(rows[0]["network"]["nominal_psf"]["psnr"], rel=1e-9)
    assert abs(again["psnr"] - without["psnr"]) > 1e-3  # the stray light reaches what the toy network delivers
    assert np.isfinite(again["psnr"])

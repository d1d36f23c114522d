"""``--device`` on every command that computes: it sets what ``device=None`` means while the command runs (and
only then), and a scene's ``device`` key that names a GPU this machine lacks is refused by ``run``, ``doctor`` and
``psf --scene`` before any work."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parents[2]
HDR = REPO / "scenes" / "hdr.toml"
COMMANDS = {"design": ["design", "--task", "streak"], "psf": ["psf"], "demo": ["demo"],
            "train": ["train", "--task", "hdr"], "evaluate": ["evaluate", "--task", "hdr"],
            "finetune": ["finetune", "--design", "d"], "tolerance": ["tolerance", "--design", "d"],
            "run": ["run", str(HDR)], "doctor": ["doctor", str(HDR)]}


@pytest.mark.parametrize("name", COMMANDS)
def test_the_command_computes_on_the_device_its_flag_names(name, monkeypatch):
    import importlib

    from doefab._devices import ENV, default_device
    from doefab.cli import main

    seen = []
    monkeypatch.setattr(importlib.import_module(f"doefab.cli.{name}"), "run",
                        lambda args: seen.append((default_device(), args.device)) or 0)
    monkeypatch.setenv(ENV, "gpu")  # what None would mean without the flag: not a device at all
    assert main([*COMMANDS[name], "--device", "CPU", "--out", "o"]) == 0
    assert seen == [("cpu", "cpu")]
    import os

    assert os.environ[ENV] == "gpu"  # the command's device ends with it


@pytest.mark.parametrize("cmd", ["run", "doctor", "psf"])
def test_a_scene_naming_a_gpu_this_machine_lacks_is_refused_before_any_work(cmd, one_clear_error, monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)

    def build(fixtures, tmp):
        (tmp / "s.toml").write_text('device = "cuda:1"\n' + HDR.read_text())
        scene = ["psf", "--scene"] if cmd == "psf" else [cmd]
        return [*scene, tmp / "s.toml"] + (["--out", tmp / "o"] if cmd != "doctor" else [])
    line = one_clear_error(build, 2, "the scene device 'cuda:1': torch")
    assert 'device = "cpu"' in line and "or --device cpu" in line and "sees no CUDA device" in line


@pytest.mark.parametrize("cmd", ["doctor", "psf"])
def test_the_flag_overrides_a_scene_device_this_machine_lacks(cmd, tmp_path, monkeypatch):
    """A scene written on a GPU workstation (``device = "cuda:1"``) runs on a laptop with ``--device cpu``: the key
    is checked as a device word when the scene loads, and against this machine only where it is used."""
    import doefab
    from doefab._devices import default_device
    from doefab.cli import main
    from doefab.errors import DoefabError

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    seen = []

    def plan(*args, **kwargs):
        seen.append(default_device())
        raise DoefabError("stopped here")

    monkeypatch.setattr(doefab, "PSFPlan", plan)
    monkeypatch.setattr("doefab.optics.psf.PSFPlan", plan)
    (tmp_path / "s.toml").write_text('device = "cuda:1"\n' + HDR.read_text())
    args = (["psf", "--scene", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o")] if cmd == "psf"
            else ["doctor", str(tmp_path / "s.toml"), "--no-timing"])
    assert main([*args, "--device", "cpu"]) == 2  # stopped at the first PSF, past the device
    assert seen and set(seen) == {"cpu"}


def test_psf_computes_on_the_scene_device_key_unless_the_flag_names_one(tmp_path, monkeypatch):
    import doefab
    from doefab._devices import ENV, default_device
    from doefab.cli import main

    from doefab.errors import DoefabError

    seen = []

    def plan(*args, **kwargs):
        seen.append(default_device())
        raise DoefabError("stopped here")

    monkeypatch.setattr(doefab, "PSFPlan", plan)
    monkeypatch.setenv(ENV, "gpu")  # what None would mean without the key: not a device at all
    (tmp_path / "s.toml").write_text('device = "AUTO"\n' + HDR.read_text())
    for flags in ([], ["--device", "cpu"]):
        assert main(["psf", "--scene", str(tmp_path / "s.toml"), *flags, "--out", str(tmp_path / "o")]) == 2
    assert seen == ["auto", "cpu"]  # the scene's key, then the flag over it


def test_run_with_the_flag_passes_a_scene_device_this_machine_lacks(tmp_path, monkeypatch):
    """``doefab run`` checks a scene's device before any folder is made, unless ``--device`` overrides it."""
    from doefab.cli import main
    from doefab.errors import DoefabError
    from doefab.pipeline import run as run_mod

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    reached = []

    def prepare(*args, **kwargs):
        reached.append(True)
        raise DoefabError("stopped here")

    monkeypatch.setattr(run_mod, "prepare_scene", prepare)
    (tmp_path / "s.toml").write_text('device = "cuda:1"\n' + HDR.read_text())
    argv = ["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o")]
    assert main(argv) == 2 and not reached  # refused at the device
    assert main([*argv, "--device", "cpu"]) == 2 and reached  # past it, stopped at the scene's checks

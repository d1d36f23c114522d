"""Devices: what ``device`` means (auto, cpu, cuda, cuda:N; None: the default), the one error a device that does not
exist gets from every computing API before any file is written, and the GPU each local Dask worker takes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import doefab
from doefab._devices import ENV, check_device, default_device, resolve_device, using_device
from doefab.errors import DoefabError

REPO = Path(__file__).resolve().parents[1]
HALF_RING = REPO / "masks" / "half-ring" / "design"


@pytest.fixture
def no_cuda(monkeypatch):
    """This machine as one whose torch sees no GPU (whatever it has)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)


@pytest.fixture
def two_gpus(monkeypatch):
    """This machine as one whose torch sees two GPUs (nothing is run on them)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)


@pytest.mark.parametrize("value", ["gpu", "cuda:x", "cpu:0", "cuda:", "cuda:01", "", 1, None])  # torch refuses cuda:01
def test_a_word_that_is_no_device_is_refused_with_the_fix(value):
    with pytest.raises(DoefabError) as exc:
        check_device(value, "device")
    msg = str(exc.value)
    assert f"device {value!r} is not a device" in msg and 'device="cpu"' in msg and "auto, cpu, cuda or cuda:N" in msg


def test_cuda_without_a_gpu_is_refused_and_names_the_cpu(no_cuda):
    for value in ("cuda", "cuda:0", "CUDA"):
        with pytest.raises(DoefabError, match=rf"device '{value}': torch .* sees no CUDA device.*device=\"cpu\""):
            check_device(value)
    assert resolve_device("auto") == torch.device("cpu") and resolve_device(None) == torch.device("cpu")


def test_a_gpu_index_that_does_not_exist_names_the_ones_that_do(two_gpus):
    with pytest.raises(DoefabError, match=r"'cuda:7': torch sees 2 CUDA devices \(cuda:0, cuda:1\).*cuda:0"):
        check_device("cuda:7", "--device")
    assert check_device("cuda:1") == "cuda:1" and check_device(" Cuda ") == "cuda"
    assert resolve_device("auto") == torch.device("cuda")  # auto: the GPU when torch sees one


def test_none_means_the_default_device_which_using_device_sets_for_this_process_and_its_workers(monkeypatch, no_cuda):
    monkeypatch.delenv(ENV, raising=False)
    assert default_device() == "auto"
    monkeypatch.setenv(ENV, "cpu")
    assert default_device() == "cpu"
    with using_device("auto"):
        assert default_device() == "auto" and resolve_device(None) == torch.device("cpu")
        import os

        assert os.environ[ENV] == "auto"  # a worker process started here inherits it
    assert default_device() == "cpu"  # restored
    monkeypatch.setenv(ENV, "gpu")
    with pytest.raises(DoefabError, match=r"DOEFAB_DEVICE 'gpu' is not a device.*DOEFAB_DEVICE=\"cpu\""):
        resolve_device(None)
    with pytest.raises(DoefabError, match="'cuda'"):
        with using_device("cuda"):
            pass


def _cam():
    return doefab.Camera(aperture_diameter=1.08e-3, doe_pitch=10.8e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                         sensor_distance=20e-3, focus_distance=5.0)


def _pair():
    return doefab.split_aperture_psf(None, _cam(), [650e-9, 550e-9, 450e-9], [5.0], 15, device="cpu")


def _mc(tmp):
    from doefab.tolerance.montecarlo import monte_carlo

    return monte_carlo(HALF_RING, {}, 1, tmp / "out", progress=False, device="gpu")


API = {  # every computing API, each given device="gpu" and whatever else it needs to start (writing under tmp/out)
    "PSFPlan": lambda tmp: doefab.PSFPlan(_cam(), [550e-9], [5.0], 15, device="gpu"),
    "split_aperture_psf": lambda tmp: doefab.split_aperture_psf(None, _cam(), [550e-9], [5.0], 15, device="gpu"),
    "optimize": lambda tmp: doefab.optimize("streak", iterations=1, camera=_cam(), out_dir=tmp / "out", progress=False,
                                            task_params={"kernel_size": 15, "arm_px": 4}, device="gpu"),
    "simulate_captures": lambda tmp: doefab.simulate_captures(np.full((3, 16, 16), 0.5), _pair(), device="gpu"),
    "load_reconstructor": lambda tmp: doefab.load_reconstructor("hdr", device="gpu"),
    "train": lambda tmp: __import__("doefab.reconstruction.train", fromlist=["train"]).train(
        "hdr", out_dir=tmp / "out", weights_dir=tmp / "out" / "w", progress=False, device="gpu"),
    "finetune_end_to_end": lambda tmp: doefab.finetune_end_to_end(HALF_RING, tmp / "out", progress=False,
                                                                  device="gpu"),
    "PSFJudge": lambda tmp: __import__("doefab.tolerance.judge", fromlist=["PSFJudge"]).PSFJudge(HALF_RING,
                                                                                                device="gpu"),
    "monte_carlo": _mc,
}


@pytest.mark.parametrize("name", API)
def test_every_computing_api_refuses_a_bad_device_before_any_work(name, tmp_path):
    with pytest.raises(DoefabError) as exc:
        API[name](tmp_path)
    assert "device 'gpu' is not a device" in str(exc.value) and 'device="cpu"' in str(exc.value)
    assert not (tmp_path / "out").exists()


def test_run_scene_computes_on_the_scenes_device_unless_told_another(tmp_path, monkeypatch):
    import doefab.pipeline.run as run_mod
    from doefab.pipeline.scene import load_scene

    text = (REPO / "scenes" / "hdr.toml").read_text()
    (tmp_path / "s.toml").write_text(f'device = "CPU"\n{text}')
    scene = load_scene(tmp_path / "s.toml")
    seen = []
    monkeypatch.setattr(run_mod, "_run_locked", lambda *a: seen.append(default_device()) or {})
    run_mod.run_scene(scene, tmp_path / "o", res={})
    run_mod.run_scene(scene, tmp_path / "o", res={}, device="auto")
    assert seen == ["cpu", "auto"]
    with pytest.raises(DoefabError, match="device 'gpu'"):
        run_mod.run_scene(scene, tmp_path / "o2", res={}, device="gpu")
    assert not (tmp_path / "o2").exists()


def test_local_dask_workers_take_one_gpu_each(two_gpus, monkeypatch):
    from doefab.tolerance.montecarlo import worker_envs

    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "4,5")
    assert [e["CUDA_VISIBLE_DEVICES"] for e in worker_envs(3, "cuda")] == ["4", "5", "4"]
    assert [e["CUDA_VISIBLE_DEVICES"] for e in worker_envs(2, "cuda:1")] == ["5", "5"]
    assert all(e[ENV] == "cuda" for e in worker_envs(2, "cuda"))  # its one GPU
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES")
    assert [e["CUDA_VISIBLE_DEVICES"] for e in worker_envs(3, "auto")] == ["0", "1", "0"]
    assert worker_envs(2, "cpu") == [{}, {}]


def test_each_local_dask_worker_starts_with_its_own_environment():
    pytest.importorskip("dask.distributed")
    import os

    from dask.distributed import Client, LocalCluster

    from doefab.tolerance.montecarlo import _local_cluster

    cluster = _local_cluster(LocalCluster, [{"CUDA_VISIBLE_DEVICES": "7"}, {"CUDA_VISIBLE_DEVICES": "6"}])
    try:
        with Client(cluster) as client:
            client.wait_for_workers(2, timeout=60)
            got = client.run(lambda: (os.environ.get("CUDA_VISIBLE_DEVICES"), os.environ.get("DOEFAB_WORKER")))
    finally:
        cluster.close()
    assert sorted(got.values()) == [("6", "1"), ("7", "1")]


def test_a_remote_worker_is_told_the_kind_of_device_not_this_machines_gpu_number():
    """Workers started one per GPU (``CUDA_VISIBLE_DEVICES=1 dask worker ...``) each see their GPU as cuda:0: the
    submitting machine's ``cuda:1`` would be refused on every one of them."""
    from doefab.tolerance.montecarlo import remote_worker_device

    assert [remote_worker_device(d) for d in ("cuda:1", "cuda", "cpu", "auto")] == ["cuda", "cuda", "cpu", "auto"]


def test_the_visible_gpus_are_those_torch_sees(monkeypatch):
    """``CUDA_VISIBLE_DEVICES`` names them, but only as many as torch sees: "-1" (GPUs hidden) or a CPU build of torch
    under a scheduler that sets the variable is no GPU."""
    from doefab._devices import visible_gpus

    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "-1")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 0)
    assert visible_gpus() == []
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "4, 5")
    assert visible_gpus() == ["4", "5"]
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES")
    assert visible_gpus() == ["0", "1"]

"""Monte Carlo over a budget: in process, in a local process pool, or on a Dask cluster; resumable; yield.

Sample i draws its errors from ``SeedSequence(seed).spawn(n)[i]``, so the numbers are the same bit for bit
whatever the number of workers or the backend. ``samples.jsonl`` opens with the run's identity (design
checksum, budget, seed, grid, level) and then one line per finished part, so an interrupted run resumes where
it stopped — and a file written for another run is refused instead of mixed in. A lost Dask worker's parts are
recomputed by Dask (futures are retried), never lost.

On a CUDA device the parts run in this process by default (the GPU computes each part's PSFs in parallel);
``workers`` > 1 then starts them with ``spawn`` (a forked process cannot use CUDA), all on that device. A
``local:N`` Dask cluster gives each worker one GPU of its own (``CUDA_VISIBLE_DEVICES``, round robin over the GPUs
this process sees; all on GPU N for ``cuda:N``); the workers of a ``tcp://`` scheduler use what they were started
with (e.g. ``CUDA_VISIBLE_DEVICES=i dask worker ...`` per GPU) and the device asked for.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
import uuid
from pathlib import Path

import numpy as np

from doefab._memory import MALLOC_ENV, keep_freed_memory
from doefab.errors import DoefabError
from doefab.io import atomic_write_text, from_json_ready, json_text, read_json
from doefab.tolerance.errors import budget_values, sample_errors
from doefab.tolerance.schedulers import parse_scheduler

__all__ = ["monte_carlo", "run_identity", "check_resumable", "keep_freed_memory", "auto_workers"]


def run_identity(design, budget: dict, seed: int, grid: int, networks: bool, weights_dir=None,
                 chain: dict | None = None) -> dict:
    """What a samples.jsonl must have been written for to be resumed: the design (level map, camera, bands,
    planes, levels), the budget, seed, grid, the mask set's alignment chain, the source of the code that computes a
    part (``conditions.model_sources_sha256``: parts of another version are not mixed in), the pixels the task's PSF
    metric counts (``Task.band_masks``: parts scored on another metric are not mixed in either) and, through networks,
    the network's weights (their SHA-256) and the scenes the network judge reads (``netjudge.judge_settings``)."""
    b = budget_values(budget)
    system = {"camera": design.camera.to_dict(), "wavelengths_m": list(design.wavelengths), "n_levels": design.n_levels,
              "depths_m": [z if math.isfinite(z) else "inf" for z in design.depths]}
    from doefab.tolerance.conditions import metric_sha256, model_sources_sha256

    out = {"design_levels_sha256": design.extra.get("levels_sha256") or _levels_sha(design.levels),
           "design_system_sha256": _digest(system), "part_model_sha256": model_sources_sha256(),
           "budget_sha256": _digest(b), "seed": int(seed), "grid": int(grid), "level": "network" if networks else "psf",
           "alignment_chain": {str(k): int(v) for k, v in sorted((chain or {}).items())},
           "metric_sha256": metric_sha256(design)}
    if networks:
        from doefab.tolerance.netjudge import judge_settings

        out["network_sha256"] = network_weights_sha(design.task, weights_dir)
        out["network_judge"] = judge_settings(networks)  # the scenes each part is judged on
    return out


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def network_weights_sha(design_task: str, weights_dir=None) -> str | None:
    """The SHA-256 its record gives of the proposed network a design of ``design_task`` is judged through."""
    from doefab.reconstruction.weights import weights_paths
    from doefab.applications import of_design

    task = getattr(of_design(design_task), "name", None)
    if task is None:
        return None
    try:
        return read_json(weights_paths(task, "proposed", weights_dir)[1]).get("weights_sha256")
    except (OSError, ValueError):
        return None


def _levels_sha(levels) -> str:
    from doefab.fabrication.levels import levels_sha256

    return levels_sha256(levels)


def check_resumable(out_dir, design, budget: dict, seed: int, grid, networks, weights_dir=None,
                    chain: dict | None = None) -> None:
    """Before any step of a study: a ``samples.jsonl`` in ``out_dir`` must have been written for this study (its
    grid too, unless ``grid`` is "auto" and not known yet), else a DoefabError names what differs — so a refused
    resume has judged nothing and changed nothing of the earlier study."""
    log = Path(out_dir) / "samples.jsonl"
    if log.is_file():
        identity = run_identity(design, budget, seed, 0 if grid == "auto" else int(grid), networks, weights_dir, chain)
        _check_header(log, log.read_text().splitlines(), identity, partial=grid == "auto")


def _check_header(log: Path, lines: list[str], identity: dict, partial: bool = False) -> None:
    try:
        head = from_json_ready(json.loads(lines[0]))["run"] if lines else None
    except (ValueError, KeyError, TypeError):
        head = None
    keys = [k for k in identity if not (partial and k == "grid")]
    if head is None or (not partial and head != identity) or any(head.get(k) != identity[k] for k in keys):
        diff = sorted(k for k in keys if head is None or head.get(k) != identity[k])
        code = "; another version of doefab's part model wrote it" if "part_model_sha256" in diff else ""
        raise DoefabError(f"{log} was written for another run (differs in {', '.join(diff) or 'its header'}{code}): "
                          f"use a new --out, or --force to start again")


def _read_log(log: Path, identity: dict) -> dict:
    done: dict = {}
    if not log.is_file():
        return done
    lines = log.read_text().splitlines()
    _check_header(log, lines, identity)
    for line in lines[1:]:
        try:
            r = from_json_ready(json.loads(line))
            done[int(r["index"])] = r
        except (ValueError, KeyError):
            continue  # a line cut by an interruption: recomputed
    return done


def _drop_cut_line(log: Path) -> None:
    """Cut a last line an interruption left without its newline (``_read_log`` skips it: the part is recomputed),
    so the next row starts a line of its own and the file stays JSON lines."""
    if not log.is_file():
        return
    data = log.read_bytes()
    if data and not data.endswith(b"\n"):
        last = data[data.rfind(b"\n") + 1:]
        try:
            json.loads(last)  # whole, only its newline lost: kept (``_read_log`` counted it done)
        except ValueError:
            with open(log, "r+b") as fh:
                fh.truncate(len(data) - len(last))
            return
        with open(log, "ab") as fh:
            fh.write(b"\n")


def monte_carlo(design_dir, budget: dict, n: int, out_dir: str | Path, seed: int = 0, supersample: int = 1,
                scheduler: str | None = None, workers: int | None = None, progress: bool = True,
                networks: bool = False, weights_dir=None, device=None) -> list[dict]:
    """``n`` sampled parts; returns every sample's errors and metrics (ordered by index). ``networks``: judge
    each part through its task's proposed network too (from ``weights_dir``; None: the shipped one).

    scheduler: None (in process, or a local process pool of ``workers``; None: ``auto_workers``, no more than fit in
    the memory available (``fields.parts_that_fit``), in process on a CUDA device), ``"local:N"`` (a Dask
    ``LocalCluster`` of N workers, one GPU each on a CUDA device) or ``"tcp://HOST:PORT"`` (an existing Dask
    scheduler). ``device``: where the parts' PSFs and networks run ("auto", "cpu", "cuda", "cuda:N"; None: the
    current default, ``doefab._devices.default_device``).
    """
    from doefab._devices import resolve_device, using_device
    from doefab.tolerance.fields import part_size, parts_that_fit
    from doefab.tolerance.study import evaluate_part, judge_for

    if device is not None:  # the default device of this call and of the workers it starts
        with using_device(device, "device"):
            return monte_carlo(design_dir, budget, n, out_dir, seed, supersample, scheduler, workers, progress,
                               networks, weights_dir)
    cuda = resolve_device(None).type == "cuda"

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "samples.jsonl"
    judge = judge_for(design_dir, supersample)
    identity = run_identity(judge.design, budget, seed, supersample, networks, weights_dir, judge.chain)
    done = _read_log(log, identity)
    _drop_cut_line(log)
    if not log.is_file():
        atomic_write_text(log, json_text({"run": identity}, indent=None) + "\n")  # never a cut header
    children = np.random.SeedSequence(seed).spawn(n)
    todo = [i for i in range(n) if i not in done]
    errs = {i: sample_errors(budget, np.random.default_rng(children[i]), seed=int(children[i].generate_state(1)[0]),
                             n_masks=judge.n_masks) for i in todo}
    bar = _bar(n, "Monte Carlo" + (" (networks)" if networks else ""), progress)
    if bar is not None:
        bar.update(len(done))
    t0 = time.perf_counter()

    def record(i, res):
        row = {"index": i, "errors": errs[i].to_json(), **res, "seconds": round(time.perf_counter() - t0, 3)}
        done[i] = row
        with open(log, "a") as fh:
            fh.write(json_text(row, indent=None) + "\n")  # strict JSON lines (jq, a browser)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(metric=f"{res['metric']:.3f}",
                            parts_per_min=f"{bar.n * 60 / max(time.perf_counter() - t0, 1e-9):.1f}")

    ddir = str(design_dir)
    wdir = None if weights_dir is None else str(weights_dir)
    if not workers:  # one per core, as many as fit in memory (``fields.parts_that_fit``), in process on a GPU
        fit = parts_that_fit(part_size(judge.design, judge.n_masks), supersample)
        workers = 1 if cuda else max(1, min(auto_workers(len(todo)), fit if fit is not None else len(todo)))
    try:
        if scheduler:
            _run_dask(scheduler, ddir, supersample, todo, errs, record, networks, weights_dir)
        elif workers > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor, as_completed

            ex = ProcessPoolExecutor(workers, initializer=_worker_init,
                                     mp_context=multiprocessing.get_context("spawn") if cuda else None)
            try:
                futs = {ex.submit(evaluate_part, ddir, supersample, errs[i].to_json(), networks, wdir): i for i in todo}
                for f in as_completed(futs):
                    record(futs[f], f.result())
            finally:  # an interruption drops the queued parts (the saved ones resume) instead of waiting for all
                ex.shutdown(wait=True, cancel_futures=True)
        else:
            keep_freed_memory()
            for i in todo:
                record(i, evaluate_part(ddir, supersample, errs[i].to_json(), networks, wdir))
    finally:
        if bar is not None:
            bar.close()
    return [done[i] for i in range(n)]


def _bar(total, desc, progress):
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="part")


def auto_workers(samples: int) -> int:
    """Worker processes for ``samples`` parts: one per usable core (``_devices.usable_cores``: a scene of ``doefab
    run --jobs`` its share), or in process (1) when there are too few parts to repay each worker's start-up (it
    builds its own judge, ~5 s for a grating design)."""
    from doefab._devices import usable_cores

    cores = usable_cores()
    return cores if cores > 1 and samples >= 4 * cores else 1


def _worker_init():
    import signal

    os.environ["DOEFAB_WORKER"] = "1"
    # the parent handles Ctrl-C and SIGTERM (it keeps the finished parts and drops the queue); a worker just
    # finishes its part, or dies with the pool
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    keep_freed_memory()
    import torch

    torch.set_num_threads(1)


def _run_dask(scheduler, ddir, supersample, todo, errs, record, networks=False, weights_dir=None):
    from doefab.tolerance.study import evaluate_part

    nw = parse_scheduler(scheduler, "--scheduler")
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise DoefabError("--scheduler needs dask.distributed: pip install 'dask[distributed]'") from None
    cluster = None
    if nw is not None:
        from doefab.tolerance.daskplugin import IgnoreCtrlC

        cluster = _local_cluster(LocalCluster, worker_envs(nw))
        client = Client(cluster)
        client.register_plugin(IgnoreCtrlC())  # Ctrl-C stops this process, which closes its workers quietly
    else:
        from doefab._devices import default_device

        client = Client(scheduler)
    try:
        fn, head = evaluate_part, ()
        if nw is None:  # a running scheduler: its workers now, and each part where it is computed (a late joiner)
            from doefab.tolerance.conditions import model_sources_sha256

            here, device = model_sources_sha256(), remote_worker_device(default_device())  # for both checks
            if not _check_worker_code(client, here):  # the parts wait for a worker: say so, not a silent bar
                print(f"doefab tolerance: the scheduler {scheduler} has no workers yet; the parts wait for one (start "
                      f"it with: dask worker {scheduler}); Ctrl-C stops and keeps the parts judged by then",
                      file=sys.stderr, flush=True)
            client.run(_set_default_device, device)
            fn, head = _part_on_worker, (here, device)
        study = uuid.uuid4().hex[:12]  # this study's own keys: a shared scheduler never answers another's part
        futs = {client.submit(fn, *head, ddir, supersample, errs[i].to_json(), networks,
                              None if weights_dir is None else str(weights_dir),
                              key=f"doefab-sample-{study}-{i}", retries=2, pure=False): i for i in todo}
        for f in as_completed(futs):
            got = f.result()
            if isinstance(got, dict) and OTHER_CODE in got:
                raise DoefabError(_other_code_text([got[OTHER_CODE]]))
            record(futs[f], got)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _check_worker_code(client, here: str) -> int:
    """Refuse a ``tcp://`` scheduler whose workers compute parts with other code than this process's, ``here``
    (``conditions.model_sources_sha256``; another doefab version or a modified copy): their parts would be mixed
    into this study without a sign. Returns how many workers it has now."""
    from doefab.tolerance.conditions import model_sources_sha256

    try:
        digests = client.run(model_sources_sha256)
    except (ImportError, AttributeError):  # a doefab without the digest: an older version
        digests = {"(some)": None}
    other = sorted(w for w, d in digests.items() if d != here)
    if other:
        raise DoefabError(_other_code_text(other))
    return len(digests)


def _other_code_text(workers: list[str]) -> str:
    return (f"the scheduler's workers {', '.join(workers)} run another version of doefab's part model than this "
            f"process: start them from the same doefab (same version and files)")


OTHER_CODE = "doefab: a worker with another part model"  # what ``_part_on_worker`` returns in place of a part


def _part_on_worker(expected: str, device: str, *args):
    """Run on a ``tcp://`` scheduler's worker: ``study.evaluate_part(*args)`` on ``device`` where the worker's part
    model is ``expected`` (this process's), else ``{OTHER_CODE: the worker's address}`` — a worker that joined after
    the study's first check is checked as the first ones were, and its part is not mixed in."""
    from doefab.tolerance.conditions import model_sources_sha256
    from doefab.tolerance.study import evaluate_part

    if model_sources_sha256() != expected:  # a few ms beside a part's seconds
        try:
            from distributed import get_worker

            name = get_worker().address
        except (ImportError, ValueError):
            name = "(a worker)"
        return {OTHER_CODE: name}
    _set_default_device(device)
    return evaluate_part(*args)


def remote_worker_device(text: str) -> str:
    """The device a ``tcp://`` scheduler's workers are told for this machine's ``text``: its kind alone ("cuda" for
    "cuda:1"), so each worker computes on the GPU it was started with (``CUDA_VISIBLE_DEVICES``), which this
    machine's GPU numbers do not name. Example: ``remote_worker_device("cuda:1") == "cuda"``."""
    return text.split(":")[0]


def _set_default_device(text: str) -> None:
    """Run on a Dask worker: ``device=None`` means ``text`` there."""
    from doefab._devices import ENV

    os.environ[ENV] = text


def worker_envs(n_workers: int, device=None) -> list[dict]:
    """The environment of each of ``n_workers`` local Dask workers on ``device`` (None: the default device): on a
    CUDA device one GPU each — ``CUDA_VISIBLE_DEVICES`` round robin over the GPUs this process sees (GPU N alone for
    ``cuda:N``) and ``DOEFAB_DEVICE=cuda`` (the worker's one GPU); on the CPU none.

    Example: with ``CUDA_VISIBLE_DEVICES=4,5``, ``worker_envs(3, "cuda")`` puts the workers on GPUs 4, 5 and 4.
    """
    from doefab._devices import ENV, resolve_device, visible_gpus

    dev = resolve_device(device)
    if dev.type != "cuda":
        return [{} for _ in range(n_workers)]
    gpus = visible_gpus()
    if dev.index is not None:
        gpus = [gpus[dev.index]]
    return [{"CUDA_VISIBLE_DEVICES": gpus[i % len(gpus)], ENV: "cuda"} for i in range(n_workers)]


def _local_cluster(local_cluster, envs: list[dict]):
    """A Dask ``LocalCluster`` (the class ``local_cluster``) of ``len(envs)`` single-threaded worker processes,
    worker i started with ``envs[i]`` added to its environment."""
    base = {"DOEFAB_WORKER": "1", "OMP_NUM_THREADS": "1", **MALLOC_ENV}
    options = dict(threads_per_worker=1, processes=True, dashboard_address=None, env=base)
    if not any(envs):
        return local_cluster(n_workers=len(envs), **options)
    import copy

    cluster = local_cluster(n_workers=0, **options)
    for i, extra in enumerate(envs):  # each worker's own environment (its GPU), kept when Dask restarts it
        spec = copy.deepcopy(cluster.new_spec)
        spec["options"]["env"] = {**base, **extra}
        cluster.worker_spec[f"doefab-{i}"] = spec
    cluster.scale(len(envs))
    return cluster

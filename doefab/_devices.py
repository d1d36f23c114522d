"""Where torch computes: the ``device`` argument of the computing API, the ``--device`` flag and the scene's
``device`` key, checked and resolved in one place.

A device is ``"auto"`` (CUDA when torch sees a GPU, else the CPU), ``"cpu"``, ``"cuda"`` (the current GPU) or
``"cuda:N"`` (GPU N), in any case, or a ``torch.device``. ``device=None`` means the current default: the one
``using_device`` sets (the command line sets it from ``--device`` or the scene's key), else the environment
variable ``DOEFAB_DEVICE``, else ``"auto"``. A device that does not exist on this machine is refused with one
error naming it and a device that works. torch is imported only when a device is checked.
"""

from __future__ import annotations

import os
import re
from contextlib import contextmanager

from doefab.errors import DoefabError

__all__ = ["DEVICE_WORDS", "ENV", "CORES_ENV", "check_device", "device_syntax",
           "resolve_device", "default_device", "using_device", "to_device",
           "describe_device", "usable_cores", "visible_gpus", "env_count"]

DEVICE_WORDS = ("auto", "cpu", "cuda", "cuda:N")
ENV = "DOEFAB_DEVICE"  # the default device of this process and the worker processes it starts
_SYNTAX = re.compile(r"^(auto|cpu|cuda)(:(?:0|[1-9]\d*))?$")  # cuda:01 is no torch device
_current: str | None = None  # set by ``using_device``
CORES_ENV = "DOEFAB_CORES"  # the cores a process may use when it shares the machine (``doefab run --jobs``)


def env_count(name: str) -> int | None:
    """The environment variable ``name`` where it holds a whole number ≥ 1 (a count or a size that doefab gives a
    process it starts), else None. Example: ``env_count("DOEFAB_CORES")`` is None where it is unset."""
    try:
        n = int(os.environ.get(name, ""))
    except ValueError:
        return None
    return n if n >= 1 else None


def usable_cores() -> int:
    """The CPU cores this process may use: ``$DOEFAB_CORES`` where set to a whole number ≥ 1 (a scene of ``doefab
    run --jobs`` gets its share), else the cores it may run on (its affinity; the machine's count where that is
    not known).

    Example: ``usable_cores() >= 1``."""
    given = env_count(CORES_ENV)
    if given is not None:
        return given
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def visible_gpus() -> list[str]:
    """The GPUs this process sees, as ``CUDA_VISIBLE_DEVICES`` names them (its first N entries where it is set, else
    0..N-1, for the N GPUs torch sees; none where torch sees none, e.g. a CPU build or ``CUDA_VISIBLE_DEVICES=-1``):
    the values that give a child process one GPU of its own.

    Example: with ``CUDA_VISIBLE_DEVICES=4,5``, ``visible_gpus() == ["4", "5"]``."""
    import torch

    count = torch.cuda.device_count() if torch.cuda.is_available() else 0  # e.g. 0 for CUDA_VISIBLE_DEVICES=-1
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None:
        return [g.strip() for g in visible.split(",") if g.strip()][:count]
    return [str(i) for i in range(count)]


def _example(name: str, value: str) -> str:
    """How the user writes ``value`` where ``name`` came from: a flag, a scene key or an API argument."""
    if name.startswith("--"):
        return f"{name} {value}"
    if name == "scene":
        return f'device = "{value}"'
    return f'{name}="{value}"'


def device_syntax(device, name: str = "device") -> str:
    """``device`` as a canonical string ("auto", "cpu", "cuda", "cuda:N") when it is written as one, whether or not
    this machine has it (a scene written on a GPU workstation reads on a laptop, where ``--device`` overrides it),
    or one ``DoefabError`` naming it (``name`` as in ``check_device``)."""
    import torch

    if isinstance(device, torch.device):
        device = str(device)
    who = f"{'' if name == 'scene' else name} {device!r}".strip()  # a scene's problems are named by their key
    if not isinstance(device, str):
        raise DoefabError(f"{who} is not a device: give a word, auto, cpu, cuda or cuda:N (e.g. "
                          f"{_example(name, 'cpu')})")
    text = device.strip().lower()
    m = _SYNTAX.match(text)
    if m is None or (m.group(1) != "cuda" and m.group(2)):
        raise DoefabError(f"{who} is not a device: give auto, cpu, cuda or cuda:N (e.g. {_example(name, 'cpu')})")
    return text


def check_device(device, name: str = "device") -> str:
    """``device`` as a canonical string ("auto", "cpu", "cuda", "cuda:N"), or one ``DoefabError`` naming it and a
    device that works on this machine. ``name``: how the user gave it ("--device", "scene" for the scene's key, or
    the API argument's name), for the fix the message shows. "auto" is always accepted."""
    import torch

    text = device_syntax(device, name)
    if not text.startswith("cuda"):
        return text
    who = f"{'the scene device' if name == 'scene' else name} {str(device)!r}"
    flag = " in the scene, or --device cpu" if name == "scene" else ""  # the flag overrides the scene's key
    if not torch.cuda.is_available():
        raise DoefabError(f"{who}: torch {torch.__version__} sees no CUDA device on this machine: use "
                          f"{_example(name, 'cpu')} (or auto){flag}, or install a CUDA build of torch "
                          f"(docs/guide/install.md)")
    count = torch.cuda.device_count()
    if ":" in text and int(text.split(":")[1]) >= count:
        have = ", ".join(f"cuda:{i}" for i in range(count))
        raise DoefabError(f"{who}: torch sees {count} CUDA device{'s' if count != 1 else ''} ({have}): use an index "
                          f"that exists, e.g. {_example(name, 'cuda:0')}, or {_example(name, 'cpu')}{flag}")
    return text


def default_device() -> str:
    """The device ``device=None`` means here: ``using_device``'s, else ``$DOEFAB_DEVICE``, else "auto"."""
    return _current or os.environ.get(ENV) or "auto"


def resolve_device(device=None, name: str = "device"):
    """The ``torch.device`` to compute on: ``device`` checked (``check_device``), None as ``default_device()``,
    "auto" as ``cuda`` when torch sees a GPU, else ``cpu``. On a GPU, float32 stays float32: TensorFloat-32 (10-bit
    mantissas in matrix products and convolutions) is switched off, so a GPU gives the CPU's numbers to float32
    rounding."""
    import torch

    given = device is not None
    text = check_device(device if given else default_device(), name if given else ENV)
    if text == "auto":
        text = "cuda" if torch.cuda.is_available() else "cpu"
    if text.startswith("cuda"):
        torch.backends.cuda.matmul.allow_tf32 = False
        torch.backends.cudnn.allow_tf32 = False
    return torch.device(text)


@contextmanager
def using_device(device, name: str = "--device"):
    """Within: ``device=None`` means ``device`` (checked first, ``name`` as in ``check_device``; None changes
    nothing), in this process and in the worker processes it starts (through ``$DOEFAB_DEVICE``)."""
    global _current
    if device is None:
        yield
        return
    text = check_device(device, name)
    old, old_env = _current, os.environ.get(ENV)
    _current, os.environ[ENV] = text, text
    try:
        yield
    finally:
        _current = old
        if old_env is None:
            os.environ.pop(ENV, None)
        else:
            os.environ[ENV] = old_env


def to_device(obj, device):
    """``obj`` with every tensor in it (nested tuples, lists and dicts too) on ``device``; other values as they
    are. On the device the tensors already live on, the same objects."""
    import torch

    if isinstance(obj, torch.Tensor):
        return obj.to(device)
    if isinstance(obj, (list, tuple)):
        return type(obj)(to_device(v, device) for v in obj)
    if isinstance(obj, dict):
        return {k: to_device(v, device) for k, v in obj.items()}
    return obj


def describe_device(device=None) -> str:
    """What ``device`` resolves to, in words: ``cpu``, or ``cuda:0 (NVIDIA H100 80GB HBM3)``."""
    import torch

    dev = resolve_device(device)
    if dev.type != "cuda":
        return "cpu"
    index = torch.cuda.current_device() if dev.index is None else dev.index
    return f"cuda:{index} ({torch.cuda.get_device_name(index)})"

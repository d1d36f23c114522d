"""Task losses: each task declares what it needs (bands, depths, kernel), its target, loss and metric."""

from __future__ import annotations

from doefab.errors import DoefabError
from doefab.tasks.base import Task
from doefab.tasks.grating import GratingTask
from doefab.tasks.halfring import HalfRingTask
from doefab.tasks.streak import StreakTask

__all__ = ["Task", "StreakTask", "GratingTask", "HalfRingTask", "TASKS", "get_task"]

#: The design tasks by name: ``"streak"`` (HDR), ``"grating"`` (hyperspectral) and ``"half-ring"`` (depth),
#: each a :class:`doefab.tasks.Task` subclass (:func:`get_task` makes one with its parameters).
TASKS = {"streak": StreakTask, "grating": GratingTask, "half-ring": HalfRingTask}


def get_task(name, **params) -> Task:
    """A task object by name (``streak``, ``grating``, ``half-ring``) with optional parameters.

    Example:

        >>> import doefab
        >>> task = doefab.get_task("grating", period_pixels=16)
        >>> task.name, task.period_pixels
        ('grating', 16)
    """
    if isinstance(name, Task):
        return name
    try:
        cls = TASKS[name]
    except (KeyError, TypeError):
        raise DoefabError(f"unknown task {name!r}: choose one of {sorted(TASKS)}") from None
    try:
        return cls(**params)
    except TypeError as exc:
        raise DoefabError(f"bad parameters for task {name!r}: {exc}") from None

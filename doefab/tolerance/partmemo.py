"""A study's steps kept on disk: whole once finished (``cached_step``), and part by part while they run
(``PartMemo``; ``memo_step`` does both), so an interrupted study resumes with what it judged.

A long step interrupted before its end (the tornado through the networks: two parts per error, each judged on the
network judge's scenes; the quantization study's level counts; the sweeps' magnitudes; the grid study's error kinds;
the surrogate's parts) would otherwise judge every part again. ``PartMemo`` keeps each part's result in a JSON-lines
file that opens with the step's key: ``memo(...)`` judges a part as ``study.evaluate_part`` does, ``memo.keep(name,
compute)`` any part the step names. A step resumed with the same key takes the parts already there instead of
judging them again, and a file of another key (another design, budget, grid, network or version of the part model)
is started afresh. The results are the same to the last bit: JSON keeps a float's every digit (a dict's whole-number
keys come back as text, as a kept step's do).
"""

from __future__ import annotations

import copy
import json
import time
from pathlib import Path

from doefab.io import atomic_write_json, atomic_write_text, from_json_ready, json_ready, json_text, read_json

__all__ = ["PartMemo", "memo_step", "cached_step", "STEPS", "IN_PART"]

STEPS = "steps"  # the folder of finished study steps a resumed study reuses (``cached_step``)
IN_PART = " (in part)"  # marks a step in a study's ``steps_reused`` that resumed with an interrupted run's parts


def _text(key) -> str:
    """A key as its canonical JSON text (sorted, numpy values and non-finite numbers as ``json_ready`` writes them)."""
    return json.dumps(json_ready(key), sort_keys=True, default=str)


class PartMemo:
    """``memo(design_dir, supersample, errors, networks, weights_dir)``: ``study.evaluate_part``'s result, from
    ``path`` where a run of this ``key`` judged that part before, else judged and appended there.

    Example: ``PartMemo(out / "steps" / "tornado.parts.jsonl", key)`` passed to ``study.tornado(evaluate=...)``."""

    def __init__(self, path: str | Path, key, evaluate=None):
        self.path, self.key, self._evaluate = Path(path), _text(key), evaluate
        self.done: dict[str, dict] = {}
        lines = self.path.read_text().splitlines() if self.path.is_file() else []
        try:
            same = bool(lines) and _text(json.loads(lines[0]).get("key")) == self.key
        except (ValueError, AttributeError):
            same = False
        for line in lines[1:] if same else []:
            try:
                row = json.loads(line)
                self.done[row["part"]] = from_json_ready(row["value"])
            except (ValueError, KeyError, TypeError):
                continue  # a line cut by an interruption: that part is judged again
        if self.done:  # the file as read, without a cut line: each later part appends a whole line of its own
            self._write([json_text({"part": p, "value": v}, indent=None) for p, v in self.done.items()])
        else:  # nothing of this key: the file is written with its first part (an empty one is no progress)
            self.path.unlink(missing_ok=True)

    def _write(self, rows: list[str]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.path, "\n".join([json_text({"key": json.loads(self.key)}, indent=None)] + rows) + "\n")

    def __call__(self, design_dir, supersample: int, errors: dict, networks: bool = False, weights_dir=None) -> dict:
        part = json.dumps([str(design_dir), int(supersample), json_ready(errors), networks,
                           None if weights_dir is None else str(weights_dir)], sort_keys=True, default=str)
        evaluate = self._evaluate
        if evaluate is None:
            from doefab.tolerance.study import evaluate_part as evaluate
        return self.keep(part, lambda: evaluate(design_dir, supersample, errors, networks, weights_dir))

    def keep(self, part: str, compute) -> dict:
        """``compute()``'s result for the part the step names ``part``: read back where this key's run kept it, else
        computed and appended. Either way as a resumed run reads it, and a copy: the kept part stays as judged.

        Example: ``memo.keep("levels 8", lambda: row_of(8))``."""
        if part not in self.done:
            row = json_text({"part": part, "value": compute()}, indent=None)
            if not self.done:
                self._write([row])
            else:
                with open(self.path, "a") as fh:
                    fh.write(row + "\n")
            self.done[part] = from_json_ready(json.loads(row)["value"])
        return copy.deepcopy(self.done[part])

    def discard(self) -> None:
        """Remove the file (its step is kept whole now)."""
        self.path.unlink(missing_ok=True)


def memo_step(out: Path, name: str, key: dict, reused: list | None, compute):
    """A study step kept whole once finished (``cached_step``) and part by part while it runs (``compute(memo)``
    judges its parts through a ``PartMemo``, steps/<name>.parts.jsonl): an interrupted step resumes with the
    parts it judged.

    Example: ``memo_step(out, "tornado", key, [], lambda memo: study.tornado(..., evaluate=memo))``."""
    memo = PartMemo(Path(out) / STEPS / f"{name}.parts.jsonl", key)
    kept = len(memo.done)  # parts an interrupted run of this study judged
    value = cached_step(out, name, key, lambda: compute(memo), reused)
    if kept and reused is not None and name not in reused:  # resumed with them: this run judged the rest
        reused.append(f"{name}{IN_PART}")
    memo.discard()  # the step is kept whole
    return value


def cached_step(out: Path, name: str, key: dict, compute, reused: list | None = None):
    """``compute()``'s result, kept in ``out/steps/<name>.json`` with the ``key`` of the study it belongs to: a
    resumed study of the same design, budget, grid and networks reuses it instead of computing it again (and
    ``name`` is appended to ``reused``)."""
    path = Path(out) / STEPS / f"{name}.json"
    try:
        rec = read_json(path)
        if rec.get("key") == from_json_ready(json.loads(json.dumps(json_ready(key), default=str))):  # as read back
            if reused is not None:
                reused.append(name)
            return rec["value"]
    except (OSError, ValueError, AttributeError):
        pass
    t = time.perf_counter()
    value = compute()
    atomic_write_json(path, {"key": key, "value": value, "seconds": round(time.perf_counter() - t, 1)})
    return value

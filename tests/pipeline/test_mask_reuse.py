"""A scene reuses the repository's committed mask set only for the same design and the same die: side and key
(the dicing outline's chamfer, which the scene's holder sets); another die gets a mask set of its own."""

from pathlib import Path
from types import SimpleNamespace

from doefab.design.design import Design
from doefab.pipeline.stages import repo_mask_set

REPO = Path(__file__).resolve().parents[2]


def test_the_committed_set_is_reused_only_for_its_own_die():
    committed = Design.load(REPO / "masks" / "half-ring" / "design")
    res = SimpleNamespace(reuse=True, settings={"design_task": "half-ring"}, committed=committed, die_m=12e-3)
    assert repo_mask_set(res, 2e-3, 1e-3) == REPO / "masks" / "half-ring"
    assert repo_mask_set(res, 2.5e-3, 1e-3) is None  # the holder asks for another key
    assert repo_mask_set(res, 2e-3, 0.7e-3) is None  # ... or a thinner substrate
    assert repo_mask_set(SimpleNamespace(**{**vars(res), "die_m": 14e-3}), 2e-3, 1e-3) is None  # a larger die
    assert repo_mask_set(SimpleNamespace(**{**vars(res), "reuse": False}), 2e-3, 1e-3) is None

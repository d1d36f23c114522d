"""A part's relief built within a memory budget (``tolerance.fields``): its transmittance computed one wavelength at
a time and its pattern areas turned a few at a time give the PSFs that building everything at once gives, to
float32 rounding, and the large-grid route holds no [wavelengths × cells] array."""

import numpy as np
import pytest
import torch

from doefab.tolerance import fields
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge

N, KERNEL, BANDS = 96, 31, 10  # 10 bands > 16 patterns / 2: a mount rotation turns the pattern areas


@pytest.fixture(scope="module")
def many_bands(grating_design):
    return grating_design(N, KERNEL, seed=2, n_bands=BANDS)


PARTS = {
    "turned, rough, tilted": PartErrors(mount_rotation=0.03, roughness=4e-9, seed=5, mount_tilt=0.02,
                                        overlay=((0.3e-6, -0.2e-6),) * 4, edge_bias=0.1e-6),
    "rough": PartErrors(roughness=4e-9, seed=7, depth_scale=(1.02, 0.99, 1.01, 0.98)),
}


@pytest.mark.parametrize("name", PARTS)
def test_a_relief_built_one_wavelength_at_a_time_gives_the_same_psfs(many_bands, monkeypatch, name):
    part = PARTS[name]
    ref = PSFJudge(many_bands).psfs(part, halves=("coded", "uncoded"), kernel=KERNEL)
    monkeypatch.setattr(fields, "FIELD_BYTES", 0)  # every grid counts as large
    monkeypatch.setattr(fields, "ROTATE_BYTES", 1)  # one pattern turned at a time
    judge = PSFJudge(many_bands)
    got = judge.psfs(part, halves=("coded", "uncoded"), kernel=KERNEL)
    assert len(judge.design.wavelengths) == BANDS
    kept = judge._relief_cache[1]
    assert isinstance(kept, fields.PerWavelength)
    assert kept.hist.shape[0] == 16  # the pattern areas are kept, not the wavelengths' transmittances
    for half in ("coded", "uncoded"):
        assert got[half].shape == ref[half].shape == (1, BANDS, KERNEL, KERNEL)
        torch.testing.assert_close(got[half], ref[half], rtol=2e-5, atol=2e-6 * float(ref[half].max()))


def test_pattern_areas_turned_a_few_at_a_time_are_those_turned_at_once(monkeypatch):
    from doefab.tolerance.relief import rotate_fields

    rng = np.random.default_rng(0)
    die = torch.from_numpy(rng.dirichlet(np.ones(8), size=40 * 40).T.astype(np.float32))  # areas summing to 1
    th, rows, cols, big, bigc = 0.04, (5, 35), (5, 35), (0, 40), (0, 40)
    plain = torch.zeros(8)
    plain[0] = 1.0
    ref = rotate_fields(die, th, rows, cols, big, bigc, 40, plain)
    monkeypatch.setattr(fields, "ROTATE_BYTES", 3 * 40 * 40 * 4)  # three patterns at a time: 3 + 3 + 2
    got = fields._rotate_patterns(die, th, rows, cols, big, bigc, 40)
    torch.testing.assert_close(got, ref, rtol=1e-6, atol=1e-6)
    torch.testing.assert_close(got.sum(dim=0), torch.ones(got.shape[1]), rtol=0, atol=1e-4)  # still a partition


def test_a_part_frees_the_last_parts_relief_and_other_grids_before_it_builds_its_own(many_bands, monkeypatch):
    """A judge keeps the relief of the last part it judged; a study holds a judge per grid. Each kept relief of
    another grid, and the judge's own, is freed before a new one is built, so that at most one grid's relief is
    held while another is built; a judge on the same grid keeps its own."""
    coarse, twin, fine = PSFJudge(many_bands), PSFJudge(many_bands), PSFJudge(many_bands, 2)
    first, second = PARTS["rough"], PARTS["turned, rough, tilted"]
    coarse.psfs(first, kernel=KERNEL)
    twin.psfs(first, kernel=KERNEL)
    held = []
    build = PSFJudge._relief_fields

    def spy(self, *args):
        held.append((self._relief_cache[1], [j._relief_cache[1] is None for j in (coarse, twin, fine)]))
        return build(self, *args)
    monkeypatch.setattr(PSFJudge, "_relief_fields", spy)
    coarse.psfs(second, kernel=KERNEL)
    assert held[-1] == (None, [True, False, True])  # its own freed first; the twin on its grid keeps its own
    fine.psfs(second, kernel=KERNEL)
    assert held[-1] == (None, [True, True, True])  # both judges of the other grid freed
    assert fine._relief_cache[1] is not None and len(held) == 2

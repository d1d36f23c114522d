"""PSFJudge's reuse of a part's PSFs: a smaller kernel served as the centre crop of a larger one computed for the
same part must equal the PSF computed directly at that kernel (an independent judge with nothing cached)."""

from dataclasses import replace

import pytest
import torch

import doefab
from doefab.design.design import Design
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge

PITCH = 5.4e-6
N = 160


@pytest.fixture(scope="module")
def design_dir(grating_design):
    return grating_design(N, 41, seed=1)


PART = PartErrors(overlay=((0.4e-6, -0.2e-6),) * 4, mount_shift=(17.3e-6, -4.1e-6), mount_rotation=2e-3,
                  depth_scale=(1.03, 0.98, 1.01, 0.99), edge_bias=0.1e-6)
ROTATED = PartErrors(mount_rotation=0.05, roughness=4e-9, seed=3)  # reaches past a 3-px margin's window
OTHER = PartErrors(mount_shift=(-31.0e-6, 0.0))


@pytest.mark.parametrize("big,part,margin_px", [(61, PART, 40), (64, PART, 40), (61, ROTATED, 3)])
def test_a_smaller_kernel_is_the_centre_crop_of_a_larger_one(design_dir, big, part, margin_px):
    """41 px (the task's) from 61 or 64 px (same and opposite parity); a relief rotated beyond the coded half's
    window, with roughness (whose random field must not depend on the halves asked for)."""
    warm = PSFJudge(design_dir, 1, margin=margin_px * PITCH)
    cold = PSFJudge(design_dir, 1, margin=margin_px * PITCH)
    with torch.no_grad():
        pair = warm.psfs(part, halves=("coded", "uncoded"), kernel=big)
        served = warm.psfs(part)["coded"]  # from the pair above
        direct = cold.psfs(part)["coded"]
    assert all(key[2] == big for key in warm._plans)  # the 41 px PSF was served, not computed
    assert pair["coded"].shape[-1] == big and served.shape == direct.shape == pair["coded"].shape[:-2] + (41, 41)
    assert float((served - direct).abs().max()) <= 1e-5 * float(direct.max())
    # the pair's uncoded half is a different PSF: serving it for the coded one would fail the check above
    c = big // 2 - 41 // 2
    assert float((pair["uncoded"][..., c:c + 41, c:c + 41] - direct).abs().max()) > 1e-3 * float(direct.max())


def test_parts_differing_only_in_their_roughness_draw_are_told_apart(design_dir):
    j = PSFJudge(design_dir, 1, margin=40 * PITCH)
    cold = PSFJudge(design_dir, 1, margin=40 * PITCH)
    a, b = (PartErrors(roughness=8e-9, roughness_corr=5e-6, seed=s) for s in (1, 2))
    with torch.no_grad():
        j.psfs(a, halves=("coded", "uncoded"), kernel=61)
        got = j.psfs(b)["coded"]
        want, first = cold.psfs(b)["coded"], PSFJudge(design_dir, 1, margin=40 * PITCH).psfs(a)["coded"]
    assert float((got - want).abs().max()) <= 1e-6 * float(want.max())
    assert float((want - first).abs().max()) > 1e-4 * float(want.max())


def test_another_part_is_never_served_from_the_last(design_dir):
    j = PSFJudge(design_dir, 1, margin=40 * PITCH)
    cold = PSFJudge(design_dir, 1, margin=40 * PITCH)
    with torch.no_grad():
        j.psfs(PART, halves=("coded", "uncoded"), kernel=61)
        got = j.psfs(OTHER)["coded"]
        want = cold.psfs(OTHER)["coded"]
        first = cold.psfs(PART)["coded"]
    assert float((got - want).abs().max()) <= 1e-6 * float(want.max())
    assert float((got - first).abs().max()) > 1e-3 * float(want.max())  # the two parts do differ


def test_a_height_map_is_reused_only_for_itself(design_dir):
    j = PSFJudge(design_dir, 1, margin=40 * PITCH)
    cold = PSFJudge(design_dir, 1, margin=40 * PITCH)
    d = j.design
    h1 = doefab.levels_to_height(d.levels, d.camera)
    h2 = h1 * 0.9
    j.height_psfs(h1, ("coded", "uncoded"), 61)
    got1, want1 = j.psf_from_height(h1), cold.psf_from_height(h1)  # served from the pair / computed
    got2, want2 = j.psf_from_height(h2), cold.psf_from_height(h2)
    assert float((got1 - want1).abs().max()) <= 1e-5 * float(want1.max())
    assert float((got2 - want2).abs().max()) <= 1e-6 * float(want2.max())
    assert float((want2 - want1).abs().max()) > 1e-3 * float(want1.max())


def test_nothing_is_shared_across_a_gap_in_front_of_a_lens_stop(design_dir):
    """In front of a lens stop the gap spreads the relief over the plan's whole window, which depends on the
    halves asked for: the coded PSF is computed for itself, equal to a cold judge's."""
    d = Design.load(design_dir)
    other = design_dir.parent / "lens_stop"
    replace(d, camera=d.camera.replace(lens_f_number=60.0)).save(other)
    part = replace(ROTATED, axial_gap=2e-3)
    warm = PSFJudge(other, 1, margin=3 * PITCH)
    cold = PSFJudge(other, 1, margin=3 * PITCH)
    assert not warm.fine.doe_is_stop
    with torch.no_grad():
        warm.psfs(part, halves=("coded", "uncoded"), kernel=61)
        got, want = warm.psfs(part)["coded"], cold.psfs(part)["coded"]
    assert float((got - want).abs().max()) <= 1e-6 * float(want.max())


def test_a_pass_computed_at_a_larger_kernel_serves_the_pair_that_follows(design_dir):
    """The tornado's PSF pass runs ``computing_at`` the network's kernel: its coded halves are kept there, and the
    network pass computes only the plain halves; every PSF equals a cold judge's."""
    j = PSFJudge(design_dir, 1, margin=40 * PITCH)
    cold = PSFJudge(design_dir, 1, margin=40 * PITCH)
    computed = []
    orig = j.plan(("coded", "uncoded"), PART.mount_shift[0], 61).psfs

    def spy(field, *a, halves=None, **kw):
        computed.append(tuple(halves))
        return orig(field, *a, halves=halves, **kw)
    j.plan(("coded", "uncoded"), PART.mount_shift[0], 61).psfs = spy
    with torch.no_grad():
        with j.computing_at(61):
            small = j.psfs(PART)["coded"]  # the task's 41 px
        pair = j.psfs(PART, halves=("coded", "uncoded"), kernel=61)
        want_small, want = cold.psfs(PART)["coded"], cold.psfs(PART, halves=("coded", "uncoded"), kernel=61)
    assert small.shape[-1] == 41 and pair["coded"].shape[-1] == 61
    assert float((small - want_small).abs().max()) <= 1e-5 * float(want_small.max())
    for h in ("coded", "uncoded"):
        assert float((pair[h] - want[h]).abs().max()) <= 1e-5 * float(want[h].max())
    assert len(computed) == 1 and computed[0] == ("uncoded",)  # the coded half came from the first pass


def test_an_even_kernel_is_cropped_from_one_a_pixel_larger(grating_design):
    """An even task kernel inside ``computing_at`` the odd network kernel one larger: the PSF comes back at the
    size asked, equal to a cold judge's, and the part can be scored against the nominal."""
    even = grating_design(N, 40, seed=1)
    j, cold = PSFJudge(even, 1, margin=40 * PITCH), PSFJudge(even, 1, margin=40 * PITCH)
    with torch.no_grad():
        with j.computing_at(41):
            got = j.psfs(PART)["coded"]
            again = j.psfs(PART)["coded"]  # served from the kept 41 px PSF
            scored = j.evaluate(PART)
        want = cold.psfs(PART)["coded"]
    assert got.shape == again.shape == want.shape and want.shape[-1] == 40
    for v in (got, again):
        assert float((v - want).abs().max()) <= 1e-5 * float(want.max())
    assert abs(scored["metric"] - cold.evaluate(PART)["metric"]) <= 1e-5

"""Network-level judge: a perfect part scores as the nominal design, and the depth network reads the measured
PSF pair it is given (its cross-blur cost volume) — a mounting error then changes what the judge reports."""

from dataclasses import replace
from pathlib import Path

import numpy as np

import pytest

from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge
from doefab.tolerance.netjudge import NetworkJudge

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def judge():
    """One validation scene of 64² px (the scene the numbers below were read on)."""
    return NetworkJudge(PSFJudge(REPO / "masks" / "half-ring" / "design", supersample=1), images=1, size=64,
                        split="val")


def test_perfect_part_reads_the_same_with_either_psf(judge):
    r = judge.evaluate(PartErrors())
    assert r["nominal_psf"].keys() == {"mae", "rmse", "log10", "delta125"}
    for k, v in r["nominal_psf"].items():
        assert r["measured_psf"][k] == pytest.approx(v, rel=1e-3, abs=1e-4)


def test_a_decentred_part_costs_the_nominal_reading_and_its_measured_pair_wins_it_back(judge, monkeypatch):
    """The DOE off centre across the split line: told the nominal PSF, the depth network reads the part's
    captures worse the larger the decenter (MAE 0.35 m perfect, 0.42 m at 0.2 mm, 0.62 m at 0.4 mm: more than 1.5×
    the perfect part's; the 500-step network read 0.42, 0.59 and 0.92 m), where a depth-blind guess (the scene's
    median depth everywhere, 0.84 m) reads far worse than the perfect part; told the part's own PSF pair, it reads
    them about as well as the perfect part's (within 15 %). The judge's 0.4 mm numbers are those of the captures it
    rendered, each reconstruction repeated here and its MAE computed with numpy (on one torch thread, as the judge
    reconstructs)."""
    import doefab.reconstruction.specs as specs
    from doefab.reconstruction.evaluate import one_thread

    perfect = judge.evaluate(PartErrors())["nominal_psf"]["mae"]
    small = judge.evaluate(PartErrors(mount_shift=(200e-6, 0.0)))
    seen = {}
    real_batch, real_measured = specs.make_batch, judge.at_network_planes
    monkeypatch.setattr(specs, "make_batch", lambda *a, **k: seen.setdefault("batch", real_batch(*a, **k)))
    # the pair the network is told: the part's own, at the network's planes (taken from the rendering planes')
    monkeypatch.setattr(judge, "at_network_planes", lambda *a, **k: seen.setdefault("pair", real_measured(*a, **k)))
    r = judge.evaluate(PartErrors(mount_shift=(400e-6, 0.0)))
    coded, uncoded, target = seen["batch"]
    t = target[0].numpy()
    with one_thread():
        mae = {label: float(np.abs(np.asarray(judge.rec(coded[0], uncoded[0], psf=psf)) - t).mean())
               for label, psf in (("nominal_psf", None), ("measured_psf", seen["pair"]))}
    for label, value in mae.items():
        assert r[label]["mae"] == pytest.approx(value, rel=1e-5), label
    blind = float(np.abs(t - np.median(t)).mean())
    assert perfect < 0.75 * blind and perfect < small["nominal_psf"]["mae"] < mae["nominal_psf"]
    assert mae["nominal_psf"] > 1.5 * perfect  # the decenter costs the nominal reading
    for measured in (small["measured_psf"]["mae"], mae["measured_psf"]):
        assert measured == pytest.approx(perfect, rel=0.15)


def test_the_error_free_part_is_judged_once_and_handed_out_by_copy(judge):
    first = judge.evaluate(PartErrors())
    first["nominal_psf"]["mae"] = -1.0  # a caller's edit must not reach the next call
    again = judge.evaluate(PartErrors())
    cold = NetworkJudge(judge.base, images=1, size=64, split="val").evaluate(PartErrors())
    assert again["nominal_psf"]["mae"] > 0
    for label in ("nominal_psf", "measured_psf"):
        for k, v in cold[label].items():
            assert again[label][k] == pytest.approx(v, rel=1e-6, abs=1e-9)


def test_the_judge_records_captures_with_the_sensor_its_network_was_trained_for(monkeypatch):
    """The network's weights record names its sensor: the judge's captures (and the crosstalk calibration behind
    them) use that noise and, hyperspectral, the response its architecture record holds; records without one
    are the default camera's (its rawtoaces curves, read here from colour-science's file)."""
    import os
    from types import SimpleNamespace

    import doefab.reconstruction.evaluate  # noqa: F401 - imported before make_batch is replaced, as in use
    import doefab.reconstruction.specs as specs
    from colour.characterisation.aces_it import ROOT_RESOURCES_RAWTOACES
    from doefab.imaging.sensor import Sensor

    bands = np.arange(400, 701, 10) * 1e-9
    nikon = Sensor("Nikon D5100", full_well_e=5000.0, read_noise_e=4.0)
    judge = NetworkJudge.__new__(NetworkJudge)
    judge.task, judge.images, judge.size, judge.split, judge._nominal = "hyperspectral", 2, 64, "test", None
    judge.base = judge._fine = None
    judge.rec = SimpleNamespace(meta={"arch": {"response": nikon.rgb(bands).tolist()}, "sensor": nikon.record()},
                                pair=SimpleNamespace(wavelengths=bands))
    judge.pair = lambda err, height=None, judge_=None: judge.rec.pair
    seen = {}

    class Stop(Exception):
        pass

    def spy(task, split, indices, size, pair, response=None, noise="default", conditions=None, **kw):
        seen.update(response=response, noise=noise, conditions=conditions)
        raise Stop

    monkeypatch.setattr(specs, "make_batch", spy)
    with pytest.raises(Stop):
        judge.evaluate(PartErrors(crosstalk=(0.05, 0.05)))
    assert np.allclose(seen["response"], nikon.rgb(bands))
    assert (seen["noise"].full_well_e, seen["noise"].read_noise_e) == (5000.0, 4.0)
    calls = []
    import doefab.tolerance.errors as errors

    monkeypatch.setattr(errors, "crosstalk_ratios", lambda err, cols, noise, **_: calls.append(noise) or (0, 0, 0, 0))
    seen["conditions"].crosstalk_for(0, 2, 64, seen["noise"])  # as make_batch calls it, with the captures' noise
    assert (calls[0].full_well_e, calls[0].read_noise_e) == (5000.0, 4.0)

    judge.rec.meta = {"arch": {}}  # shipped weights recorded before sensors were
    t, noise = judge.sensor()
    data = np.genfromtxt(os.path.join(ROOT_RESOURCES_RAWTOACES, "CANON_EOS_5DMark_II_RGB_Sensitivities.csv"),
                         delimiter=",", names=True)
    canon = np.stack([np.interp(bands * 1e9, data["wavelength"], data[c]) for c in ("R", "G", "B")])
    assert np.allclose(t, canon / canon.sum(axis=1).max(), atol=1e-6)
    assert (noise.full_well_e, noise.read_noise_e) == (25000.0, 3.0)


def _bare_judge(task: str, images: int, size: int):
    """A NetworkJudge of ``task``'s shipped proposed network whose PSF judges are not built (a test sets them)."""
    from doefab.reconstruction.loader import load_reconstructor

    judge = NetworkJudge.__new__(NetworkJudge)
    judge.task, judge.images, judge.size, judge.split, judge._nominal, judge._fine = task, images, size, "test", None, None
    judge.rec = load_reconstructor(task, "proposed")
    return judge


def test_the_error_free_part_scores_what_the_evaluation_scores_on_the_same_scenes(tmp_path):
    """The judge's captures are the evaluation's: the error-free part (the nominal PSF pair) in a camera with the
    shipped budget's crosstalk, judged on two test scenes of 64² px, scores on each scene exactly what ``doefab
    evaluate``'s proposed network scores on the same two scenes captured through that part under that crosstalk
    (its table's number for a test run through the error-free part)."""
    from dataclasses import replace

    from doefab.reconstruction.evaluate import evaluate
    from doefab.reconstruction.specs import psf_pair
    from doefab.tolerance.conditions import Conditions
    from doefab.tolerance.errors import load_budget, sensor_errors

    judge = _bare_judge("hdr", 2, 64)
    judge.base = None  # HDR renders through the network's own planes
    pair, _ = psf_pair("hdr")
    judge.pair = lambda err, height=None, judge_=None: pair
    camera = replace(PartErrors(), **sensor_errors(load_budget()))
    assert any(camera.crosstalk) and camera.calibrated
    got = judge.scenes(camera)
    table = evaluate("hdr", tmp_path, images=2, size=64, variants=("proposed",), progress=False, split="test",
                     conditions=Conditions(name="honest", parts=[pair], crosstalk=camera, split="test"))
    rows, means = table["per_image"]["rows"]["proposed"], judge.means(got)["nominal_psf"]
    for k in rows[0]:
        assert got["nominal_psf"][k] == pytest.approx([r[k] for r in rows], rel=1e-9, abs=1e-12), k
        assert means[k] == pytest.approx(table["rows"]["proposed"][k], rel=1e-9), k


def test_the_depth_judge_renders_between_the_networks_planes_and_tells_it_the_part_at_its_own(monkeypatch):
    """Depth scenes are rendered through the part's PSFs at the evaluation's fine planes (``fine_planes``: 65
    between 1 and 5 m, the network's 17 and three between each two of them), while the network, told the part's
    measured pair, gets it at its own 17 planes: taken from the rendering planes' PSFs, computed once for the
    part's errors."""
    import torch

    import doefab.reconstruction.evaluate  # noqa: F401 - imported before make_batch is replaced, as in use
    import doefab.reconstruction.specs as specs
    import doefab.tolerance.judge as judge_mod
    from doefab.tolerance.conditions import fine_planes

    judge = _bare_judge("depth", 1, 64)
    network_planes = np.array(judge.rec.pair.depths)
    asked = []

    class FakeJudge:  # PSFs whose value at each plane is that plane's depth; records what it was asked
        def __init__(self, design, supersample=1, margin=None, chain=None, device=None):
            self.design, self.supersample, self.margin, self.chain, self.device = design, supersample, margin, chain, device

        def psfs(self, err, halves, kernel):
            asked.append((len(self.design.depths), err))
            shape = (len(self.design.depths), len(self.design.wavelengths), kernel, kernel)
            z = torch.tensor(self.design.depths, dtype=torch.float64)[:, None, None, None]
            return {h: z.expand(shape).clone() for h in halves}

        def take_planes(self, other, source):
            taken.append((self, other, source))

        def source_of(self, err, height=None):
            return judge_mod.psf_source(err, height)

    from doefab.design.design import Design

    judge.base = FakeJudge(Design.load(REPO / "masks" / "half-ring" / "design"))
    monkeypatch.setattr(judge_mod, "PSFJudge", FakeJudge)
    seen, told, taken = {}, [], []

    def batch(task, split, indices, size, pair, response=None, noise="default", conditions=None, images=None):
        seen["rendered"] = conditions.pair_for(indices[0], pair)
        return torch.zeros(1, 3, size, size), torch.zeros(1, 3, size, size), torch.full((1, size, size), 2.0)

    monkeypatch.setattr(specs, "make_batch", batch)
    monkeypatch.setattr(judge, "rec", type("Rec", (), {
        "pair": judge.rec.pair, "meta": judge.rec.meta,
        "__call__": lambda self, c, u, psf=None: told.append(psf) or np.full((64, 64), 2.5)})())
    err = PartErrors(mount_shift=(1e-4, 0.0))
    judge.evaluate(err)
    fine = np.array(fine_planes(network_planes))
    rendered = np.array(seen["rendered"].depths)
    assert rendered == pytest.approx(fine) and len(rendered) == 65
    on_a_network_plane = np.isclose(rendered[:, None], network_planes[None, :], rtol=0, atol=1e-9).any(axis=1)
    assert int(on_a_network_plane.sum()) == 17  # every network plane, and three between each two
    assert seen["rendered"].coded[:, 0, 0, 0].numpy() == pytest.approx(fine, rel=1e-6)  # computed on the fine planes
    measured = told[1]
    assert told[0] is None and np.array(measured.depths) == pytest.approx(network_planes)
    # the fine planes' own PSFs at the network's planes, each at its plane, and no second computation
    for half in (measured.coded, measured.uncoded):
        assert half[:, 0, 0, 0].numpy() == pytest.approx(network_planes, rel=1e-6)
    assert [n for n, _ in asked] == [65] and all(e == err for _, e in asked)
    # the part's PSF metric is then served the same planes: the base judge keeps the rendering judge's at them
    assert taken == [(judge.base, judge.render_judge, judge_mod.psf_source(err))]
    shifted = replace(seen["rendered"], depths=tuple(z * (1 + 1e-6) for z in seen["rendered"].depths))
    assert judge.at_network_planes(shifted) is None  # planes not among them: the pair is computed on its own


def test_the_judges_scenes_are_checked_before_any_work_and_name_the_studys_run():
    """A bad scene count, size or split is refused naming the setting, its value and one that works; the scenes a
    study's parts were judged on are part of its run's identity (a study resumed on other scenes is another run)."""
    from doefab.design.design import Design
    from doefab.errors import DoefabError
    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.montecarlo import run_identity
    from doefab.tolerance.netjudge import SCENES, SIZE, judge_settings

    assert judge_settings(True) == {"images": SCENES, "size": SIZE, "split": "test"}
    for bad, needle in (({"images": 0}, r"images = 0 .* e\.g\. 8"), ({"size": 100}, r"size = 100 px .* e\.g\. 256"),
                        ({"split": "train"}, r"split = 'train' .* val, test, e\.g\. test"),
                        ({"scenes": 3}, r"\['scenes'\] are not known: give images, size or split")):
        with pytest.raises(DoefabError, match=needle):
            judge_settings(bad)
    d, budget = Design.load(REPO / "masks" / "streak" / "design"), load_budget()
    two = run_identity(d, budget, 0, 1, {"images": 2, "size": 64})
    assert two["network_judge"] == {"images": 2, "size": 64, "split": "test"}
    assert two != run_identity(d, budget, 0, 1, {"images": 3, "size": 64})
    assert run_identity(d, budget, 0, 1, True)["network_judge"]["images"] == SCENES
    assert "network_judge" not in run_identity(d, budget, 0, 1, False)

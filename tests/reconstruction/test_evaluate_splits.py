"""What the split digest covers, the final test set and its ledger, and evaluations that do not depend on the
machine's thread count (issue 38, rows 8, 9 and 11)."""

import hashlib
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from doefab.reconstruction import data
from doefab.reconstruction import evaluate as ev

QUICK = dict(images=1, size=64, progress=False, variants=("uncoded_only",))  # the shipped HDR network, clean


def test_the_split_digest_follows_what_makes_the_scenes(monkeypatch, tmp_path):
    """One photograph's pixel, a byte of the illuminant library, the scene generator's source, a split's part
    seed or the part model's source each change the digest; the library only the hyperspectral one's."""
    import doefab.io
    from doefab.reconstruction import illuminant

    hdr, hs = data.split_digest("hdr"), data.split_digest("hyperspectral")
    real = data._images

    def one_pixel_brighter(pool):
        imgs = real(pool)
        if pool != "test":
            return imgs
        a = imgs[0].copy()
        a[0, 0, 0] += 0.01
        return (a, *imgs[1:])

    monkeypatch.setattr(data, "_images", one_pixel_brighter)
    assert data.split_digest("hdr") != hdr
    monkeypatch.undo()

    lib = tmp_path / "illuminants.csv"
    text = illuminant.LIBRARY_PATH.read_text()
    lib.write_text(text.replace(",", ", ", 1))  # the same numbers, other bytes: another file
    monkeypatch.setattr(illuminant, "LIBRARY_PATH", lib)
    assert data.split_digest("hyperspectral") != hs and data.split_digest("hdr") == hdr
    monkeypatch.undo()

    src = tmp_path / "data.py"
    src.write_text(Path(data.__file__).read_text().replace("rng.uniform(0.6, 1.4, (3, 1, 1))",
                                                           "rng.uniform(0.5, 1.4, (3, 1, 1))"))
    monkeypatch.setattr(data, "__file__", str(src))
    assert data.split_digest("hdr") != hdr
    monkeypatch.undo()

    monkeypatch.setattr(data, "PART_SEEDS", {**data.PART_SEEDS, "test": 34})
    assert data.split_digest("hdr") != hdr
    monkeypatch.undo()

    monkeypatch.setattr(doefab.io, "sources_sha256", lambda root, packages: "another part model")
    assert data.split_digest("hdr") != hdr


def test_an_evaluation_says_how_a_networks_splits_differ_from_its_own():
    now = data.split_components("hdr")
    same = {"splits_sha256": data.split_digest("hdr", now), "splits_components": now}
    assert ev._splits_state(same, "hdr", now) == "the same splits"
    code = {"splits_sha256": "0" * 64, "splits_components": {**now, "generator": "0" * 64, "parts": "1" * 64}}
    assert ev._splits_state(code, "hdr", now) == ("the same split content, made by other code or files since "
                                                  "training (parts, generator)")
    content = {"splits_sha256": "0" * 64, "splits_components": {**now, "splits": "0" * 64}}
    assert ev._splits_state(content, "hdr", now) == ("ANOTHER split definition (splits): the test scenes may hold "
                                                     "training content")
    older = {"splits_sha256": data.split_digest_v1("hdr")}  # what the weights recorded before the components
    assert ev._splits_state(older, "hdr", now).startswith("the same photographs, seeds and spectra by name")
    assert ev._splits_state({"splits_sha256": "0" * 64}, "hdr", now).startswith("ANOTHER split definition")


def test_the_final_split_draws_new_scenes_from_the_test_content():
    assert data.SPLIT_SEEDS["final"] not in {s for k, s in data.SPLIT_SEEDS.items() if k != "final"}
    assert data.PART_SEEDS["final"] not in {s for k, s in data.PART_SEEDS.items() if k != "final"}
    final, test = data.split_images("final"), data.split_images("test")
    assert len(final) == len(test) and all(a is b for a, b in zip(final, test))
    for i in range(3):
        a = data.hdr_sample(data.sample_rng("final", i), 64, "final")
        b = data.hdr_sample(data.sample_rng("test", i), 64, "test")
        assert a.shape == b.shape and not np.array_equal(a, b)


def test_only_val_test_and_final_are_evaluated(tmp_path):
    from doefab.errors import DoefabError

    with pytest.raises(DoefabError, match="split 'train' is not one of val, test, final"):
        ev.evaluate("hdr", tmp_path / "e", split="train", **QUICK)
    assert not (tmp_path / "e").exists()


def test_each_read_of_the_final_split_is_logged_in_the_output_folder(tmp_path):
    final = ev.evaluate("hdr", tmp_path / "f", split="final", **QUICK)
    ev.evaluate("hdr", tmp_path / "f", split="final", **QUICK)
    assert final["split"] == "final" and final["seed"] == data.SPLIT_SEEDS["final"]
    lines = (tmp_path / "f" / ev.FINAL_LEDGER).read_text().splitlines()
    assert lines[0].startswith("| date (UTC) | code | task | what was read |") and len(lines) == 4
    sha = final["weights"]["uncoded_only"]["sha256"]
    for line in lines[2:]:
        assert f"| {final['code']} | hdr | 1 scenes of 64² px, clean captures; uncoded_only (weights {sha[:12]})" \
            in line


def test_a_read_of_the_final_split_that_fails_while_scoring_is_logged_too(tmp_path, monkeypatch):
    """The ledger line is written before any scene is scored: a read that fails (or is interrupted) after it has
    seen final scenes still counts."""
    def broken(*args, **kwargs):
        raise RuntimeError("interrupted while scoring")

    monkeypatch.setattr(ev, "_score", broken)
    with pytest.raises(RuntimeError):
        ev.evaluate("hdr", tmp_path / "f", split="final", **QUICK)
    lines = (tmp_path / "f" / ev.FINAL_LEDGER).read_text().splitlines()
    assert len(lines) == 3 and "| hdr | 1 scenes of 64² px, clean captures; uncoded_only (weights " in lines[2]
    assert not (tmp_path / "f" / "metrics.json").exists()


def test_an_evaluation_does_not_depend_on_the_threads_torch_was_given(tmp_path):
    """The same evaluation with torch set to 2 threads and to 1 beforehand: the same numbers to the last bit, the
    thread count restored, the evaluation's threads, library versions and weights' SHA-256 recorded."""
    from doefab.reconstruction.weights import weights_paths

    before = torch.get_num_threads()
    got = {}
    try:
        for n in (2, 1):
            torch.set_num_threads(n)
            got[n] = ev.evaluate("hdr", tmp_path / str(n), split="val", **QUICK)
            assert torch.get_num_threads() == n
    finally:
        torch.set_num_threads(before)
    assert json.dumps(got[2]["per_image"]["rows"]) == json.dumps(got[1]["per_image"]["rows"])  # NaN too
    assert not (tmp_path / "2" / ev.FINAL_LEDGER).exists()  # only a read of the final split is logged
    saved = json.loads((tmp_path / "2" / "metrics.json").read_text())
    assert saved["threads"] == 1
    assert saved["units"] == {"psnr_highlight": "dB", "psnr": "dB", "rmse_highlight": "1", "rmse": "1"}
    assert set(saved["scales"]) == {"rmse_highlight", "rmse"} and "clipping level" in saved["scales"]["rmse"]
    assert {"python", "torch", "numpy", "scipy", "scikit-image"} <= set(saved["versions"])
    assert saved["versions"]["torch"].split("+")[0] == torch.__version__.split("+")[0]
    pt, _ = weights_paths("hdr", "uncoded_only")
    assert saved["weights"]["uncoded_only"]["sha256"] == hashlib.sha256(pt.read_bytes()).hexdigest()


def test_the_main_job_scores_the_test_split_and_says_so(monkeypatch, tmp_path):
    import doefab.reconstruction.evaluate as evaluate_module
    import doefab.tolerance.conditions as conditions
    from doefab.pipeline import stages

    calls = []

    def fake_evaluate(task, out, **kw):
        calls.append(kw)
        return {"rows": {}, "split": kw.get("split", "test")}

    monkeypatch.setattr(evaluate_module, "evaluate", fake_evaluate)
    monkeypatch.setattr(conditions, "for_splits", lambda *a, **k: {"test": None})
    monkeypatch.setattr(stages, "_design_sha", lambda folder: "0" * 64)
    scene = SimpleNamespace(reconstruction={"weights": "shipped"}, task="hdr", tolerance=None)
    res = SimpleNamespace(reuse=True, sensor=None, settings={"design_task": "streak"})
    r = stages.stage_reconstruction(scene, res, tmp_path / "rec",
                                    True)
    assert [c["split"] for c in calls] == ["test"] and r["split"] == "test"
    assert "from the test split (not the final test set" in r["why"]

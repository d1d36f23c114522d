"""Where weights are written (``reconstruction.weights.weights_target``): never over a file of the user's."""

import json

import pytest

from doefab.errors import DoefabError


def test_train_never_replaces_a_users_file_in_weights_dir(tmp_path):
    from doefab.reconstruction.weights import weights_target

    w = tmp_path / "w"
    w.mkdir()
    (w / "hdr_proposed.json").write_text('{"mine": 1}')
    with pytest.raises(DoefabError, match="not written by doefab"):
        weights_target(w, tmp_path, task="hdr", variant="proposed")
    assert weights_target(w, tmp_path, task="hdr", variant="coded_only") == w  # other names are free
    (w / "hdr_proposed.json").write_text(json.dumps({"format": "doefab weights 1", "task": "hdr",
                                                     "variant": "proposed"}))
    assert weights_target(w, tmp_path, task="hdr", variant="proposed") == w  # doefab's own: replaced


def test_replace_shipped_is_refused_before_training_where_the_package_folder_is_read_only(tmp_path, monkeypatch):
    """A system-wide install's weights folder is not the user's to write: said before any training."""
    import os

    from doefab.reconstruction import weights

    shipped = tmp_path / "site-packages" / "doefab" / "weights"
    shipped.mkdir(parents=True)
    monkeypatch.setattr(weights, "WEIGHTS_DIR", shipped)
    assert weights.weights_target(None, tmp_path, replace_shipped=True) == shipped
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if os.path.samefile(p, shipped) else real(p, mode))
    with pytest.raises(DoefabError, match=r"--replace-shipped .*weights: .* is not writable .*: drop --replace-shipped and give a --weights-dir"):
        weights.weights_target(None, tmp_path, replace_shipped=True)

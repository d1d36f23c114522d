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

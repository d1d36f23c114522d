"""``doefab psf``: --force replaces only doefab's own output, which carries its marker."""

from doefab.cli import main
from doefab.io import MARKER


def test_force_replaces_only_own_output_and_marker_is_written(tmp_path, capsys):
    out = tmp_path / "p"
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out)]) == 0
    assert (out / MARKER).is_file()
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out), "--force"]) == 0

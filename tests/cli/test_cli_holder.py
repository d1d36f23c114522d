"""``doefab holder``: a parameter outside its stated bounds is named with them first."""

import pytest

from cli_helpers import run_cli


@pytest.mark.parametrize("setting, needle", [("clearance_mm=10", "clearance_mm 10 is outside 0.05–1 mm"),
                                             ("thread_diameter_mm=1e9", "thread_diameter_mm 1e+09 is outside 20–150 mm")])
def test_holder_names_the_parameter_and_its_bound(tmp_path, capsys, setting, needle):
    rc, _, err = run_cli(["holder", "--out", tmp_path / "h1", "--set", setting], capsys)
    assert rc == 2 and needle in err and "washers" not in err and "flange" not in err

"""Flag parsers (``cli._args``): a unit hint, when followed, is accepted."""

import pytest


def test_unit_hint_when_followed_is_accepted():
    from doefab.cli._args import wavelength_nm

    with pytest.raises(Exception, match="write 550"):
        wavelength_nm("5.5e-07")
    assert wavelength_nm("550") == 550.0

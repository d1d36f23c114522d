"""Every subcommand's --help reads as plain text in a terminal: the descriptions come from the modules'
docstrings, whose reStructuredText literals and roles (``x``, :doc:`x`) are shown as x."""

import re

from doefab.cli import _plain, build_parser


def test_no_subcommand_help_shows_restructuredtext_markup():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert len(sub.choices) >= 15
    for name, p in sub.choices.items():
        text = p.format_help()
        assert not re.search(r"``|:[a-z]+:`", text), name
        assert f"doefab {name}" in text


def test_plain_keeps_the_words():
    assert _plain("``doefab run SCENE``: see :doc:`/guide/x` and `y`") == "doefab run SCENE: see /guide/x and y"
    assert _plain(None) is None

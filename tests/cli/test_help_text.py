"""Every subcommand's --help reads as plain text in a terminal: the descriptions come from the modules'
docstrings, whose reStructuredText literals and roles (``x``, :doc:`x`) are shown as x."""

import re

from doefab.cli import _plain, build_parser


def _parsers(parser, name="doefab"):
    """Every parser under ``parser`` with its command words, the subcommands' own (``scene new``) included."""
    for action in parser._actions:
        if action.dest != "help" and hasattr(action, "choices") and isinstance(action.choices, dict):
            for word, child in action.choices.items():
                yield f"{name} {word}", child
                yield from _parsers(child, f"{name} {word}")


def test_no_subcommand_help_shows_restructuredtext_markup():
    found = list(_parsers(build_parser()))
    assert len(found) >= 17 and "doefab scene new" in dict(found)
    for name, p in found:
        text = p.format_help()
        assert not re.search(r"``|:[a-z]+:`", text), name
        assert name in text


def test_a_flag_whose_help_tells_its_default_is_not_told_it_again():
    """"(default: all three) (default: proposed,coded_only,uncoded_only)": argparse's note is added only where the
    help has none and there is a default to tell."""
    for name, p in _parsers(build_parser()):
        for action in p._actions:
            raw = action.help or ""
            help_text = p._get_formatter()._get_help_string(action) if raw else ""
            if "default" in raw.lower():  # the help tells it: argparse adds nothing
                assert help_text == raw, (name, help_text)
            assert "(default: None)" not in help_text and "(default: False)" not in help_text, (name, help_text)
    evaluate = dict(_parsers(build_parser()))["doefab evaluate"].format_help()
    assert "(default: 16)" in evaluate  # a default the help does not tell is still told
    design = dict(_parsers(build_parser()))["doefab design"].format_help()
    assert "(default: 0)" in design  # --seed 0: a default of 0 is told (0 == False)


def test_doefab_alone_is_a_usage_error_with_the_help_on_stderr(capsys):
    from doefab.cli import main

    assert main([]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "SUBCOMMAND" in err and "exit status" in err


def test_plain_keeps_the_words():
    assert _plain("``doefab run SCENE``: see :doc:`/guide/x` and `y`") == "doefab run SCENE: see /guide/x and y"
    assert _plain(None) is None

"""Wrong inputs of the public API ``doefab.__all__``: the input sweep's API cases (tables in input_sweep.py), each
a ``doefab.DoefabError`` naming the argument; and the sweep covers every subcommand and every public name."""

from input_sweep import (test_api_argument, test_api_path,  # noqa: F401 - collected here
                         test_every_command_line_case_has_its_subcommands_file, test_the_sweep_covers_the_whole_public_api)

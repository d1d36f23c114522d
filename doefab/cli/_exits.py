"""The command line's exit statuses and its SIGTERM exception (a leaf: every subcommand may import it).

Example: ``doefab run`` exits ``EXIT_CHECK`` (3) when a stage's own checks fail, ``EXIT_TERMINATED`` (143) on
SIGTERM.
"""

from __future__ import annotations

__all__ = ["EXIT_OK", "EXIT_INTERNAL", "EXIT_USAGE", "EXIT_CHECK", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "Terminated"]

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_CHECK, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 3, 130, 143


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so it unwinds (staging folders, partial outputs) like Ctrl-C."""

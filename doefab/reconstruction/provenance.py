"""What a result needs to be reproduced: the installed versions of the libraries its numbers depend on and the code
that ran (``library_versions``, ``code_version``), recorded by evaluations (``metrics.json``) and by trained
networks' weights records."""

from __future__ import annotations

from pathlib import Path

__all__ = ["library_versions", "code_version", "LIBRARIES"]

LIBRARIES = ("torch", "numpy", "scipy", "scikit-image", "colour-science")


def library_versions() -> dict:
    """{name: installed version} of the libraries an evaluation's numbers depend on (``LIBRARIES``) and Python."""
    import platform
    from importlib import metadata

    found = {"python": platform.python_version()}
    for name in LIBRARIES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


def code_version() -> str:
    """The git commit of the doefab source tree that runs (with "with uncommitted changes" when its tracked files
    differ from it), or doefab's version when it is not a git checkout."""
    import subprocess

    import doefab

    root = Path(__file__).resolve().parents[2]
    if (root / ".git").exists():
        try:
            git = ["git", "-C", str(root)]
            head = subprocess.run(git + ["rev-parse", "--short=12", "HEAD"], capture_output=True, text=True, timeout=30)
            dirty = subprocess.run(git + ["status", "--porcelain", "--untracked-files=no"], capture_output=True,
                                   text=True, timeout=60)
            if head.returncode == 0:
                return f"git {head.stdout.strip()}" + (" with uncommitted changes" if dirty.stdout.strip() else "")
        except (OSError, subprocess.SubprocessError):
            pass
    return f"doefab {doefab.__version__} (not a git checkout)"

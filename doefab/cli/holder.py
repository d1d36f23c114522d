"""``doefab holder``: the parametric DOE holder (see holder_cad; lengths in mm)."""

from __future__ import annotations

import argparse


def register(sub) -> None:
    from holder_cad.cli import add_arguments

    p = sub.add_parser("holder", help="build and check the 3D-printable DOE holder",
                       description=__doc__, formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from holder_cad.cli import run as _run

    return _run(args)

"""Wrong inputs of ``doefab psf``: the input sweep's cases of this subcommand (tables and checks in
input_sweep.py), each one clear error, nothing created or changed, no job started."""

from input_sweep import sweep

globals().update(sweep("psf"))

"""Tolerance: fabricated and misaligned DOEs, judged on the PSFs (and, where weights exist, the networks)."""

"""Fabrication: level conventions, photomask export and verification."""

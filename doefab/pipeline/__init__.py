"""The scene pipeline: a scene file → design → masks → holder → captures/reconstruction → tolerance → report."""

"""The README's picture: the top of a run's report.html as headless Chromium renders it.

Run after the main job: .venv/bin/python benchmarks/report_screenshot.py out/run/hyperspectral/report.html

Writes docs/report_hyperspectral_top.png (1200 × 1000 px).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    report = Path(sys.argv[1] if len(sys.argv) > 1 else "out/run/hyperspectral/report.html").resolve()
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None or not report.is_file():
        sys.exit(f"needs Debian's chromium and a report ({report})")
    out = ROOT / "docs" / "report_hyperspectral_top.png"
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                        "--disable-background-networking", "--disable-component-update", "--disable-sync",
                        f"--user-data-dir={profile}", "--hide-scrollbars", "--window-size=1200,1000",
                        f"--screenshot={out}", report.as_uri()], check=True, capture_output=True, timeout=120)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

"""doefab as a package, not a checkout: the built wheel, installed into a fresh folder, runs a scene file from
a folder outside the repository, with the committed designs and shipped networks it carries."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    root = tmp_path_factory.mktemp("wheel")
    src = root / "src"  # build from a copy: a build in place would leave build/ and egg-info in the checkout
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        if (REPO / name).is_file():
            shutil.copy(REPO / name, src / name)
    for pkg in ("doefab", "holder_cad"):
        shutil.copytree(REPO / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    subprocess.run(pip + ["wheel", str(src), "--no-deps", "--no-build-isolation", "-w", str(root / "dist")],
                   check=True, cwd=root)
    wheel = next((root / "dist").glob("doefab-*.whl"))
    # the dependencies are this environment's; doefab itself only from the wheel
    subprocess.run(pip + ["install", "--no-deps", "--target", str(root / "site"), str(wheel)], check=True, cwd=root)
    work = root / "elsewhere"
    work.mkdir()
    env = {**os.environ, "PYTHONPATH": str(root / "site"), "DOEFAB_CACHE": str(root / "cache"),
           "MPLBACKEND": "Agg"}
    return root, work, env, wheel


def _py(code: str, work: Path, env: dict) -> str:
    r = subprocess.run([sys.executable, "-c", code], cwd=work, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout


def test_the_wheel_carries_the_designs_weights_and_data(installed):
    root, work, env, wheel = installed
    import zipfile

    names = zipfile.ZipFile(wheel).namelist()
    for need in ("doefab/designs/streak.npz", "doefab/designs/grating.npz", "doefab/designs/half-ring.npz",
                 "doefab/weights/hdr_proposed.pt", "doefab/weights/illuminants.csv", "doefab/tolerance/budget.toml"):
        assert need in names, need
    assert not any(n.startswith(("masks/", "tests/", "benchmarks/")) for n in names)
    out = _py("import doefab, numpy as np\n"
              "print(doefab.__file__)\n"
              "rec = doefab.load_reconstructor('hdr')\n"
              "coded = np.full((3, 64, 64), 0.25, np.float32)\n"
              "y = rec(coded, coded)\n"
              "print(tuple(y.shape), bool(np.isfinite(np.asarray(y)).all()))\n", work, env)
    lines = out.strip().splitlines()
    assert lines[0].startswith(str(root / "site")), lines[0]  # not the checkout's doefab
    assert lines[-1] == "(3, 64, 64) True"


def test_the_wheel_runs_a_scene_from_any_folder(installed):
    root, work, env, _ = installed
    scene = work / "my_camera.toml"
    scene.write_text('task = "hdr"\nstages = ["design", "masks", "report"]\n[camera]\npreset = "hdr"\n')
    r = subprocess.run([sys.executable, "-m", "doefab", "run", str(scene), "--quick", "--out", str(work / "run")],
                       cwd=work, env=env, capture_output=True, text=True)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-3000:])
    assert "reused" in r.stdout  # the committed design, from the package
    layers = sorted((work / "run" / "masks").glob("*.gds"))
    assert len(layers) >= 1 and (work / "run" / "masks" / "manifest.json").is_file()
    assert (work / "run" / "report.html").is_file()

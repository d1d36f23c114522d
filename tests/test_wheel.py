"""doefab as a package, not a checkout: the built wheel, installed into a fresh folder, runs a scene file from
a folder outside the repository, with the committed designs and shipped networks it carries."""

from __future__ import annotations

import os
import re
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
    # a fresh virtual environment: doefab only from the wheel (pip install, not editable), its dependencies from
    # this environment's site-packages by a path entry (whose own .pth files, the checkout's editable hook among
    # them, are not processed)
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, cwd=root)
    site = next(venv.glob("lib/python3*/site-packages"))
    host = [p for p in sys.path if p.endswith("site-packages") and Path(p).is_dir()]
    (site / "zz_dependencies.pth").write_text("\n".join(host) + "\n")
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "--disable-pip-version-check", "-q", "install",
                    "--no-deps", "--no-index", str(wheel)], check=True, cwd=root)
    work = root / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(DOEFAB_CACHE=str(root / "cache"), MPLBACKEND="Agg", PATH=f"{venv / 'bin'}:{env.get('PATH', '')}")
    return root, work, env, wheel, venv


def _py(code: str, work: Path, env: dict, venv: Path) -> str:
    r = subprocess.run([str(venv / "bin" / "python"), "-c", code], cwd=work, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout


def test_the_wheel_carries_the_designs_weights_and_data(installed):
    root, work, env, wheel, venv = installed
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
              "print(tuple(y.shape), bool(np.isfinite(np.asarray(y)).all()))\n", work, env, venv)
    lines = out.strip().splitlines()
    assert lines[0].startswith(str(venv)), lines[0]  # the installed wheel, not the checkout's doefab
    assert lines[-1] == "(3, 64, 64) True"


TINY_CAMERA = """task = "hdr"
stages = ["design", "masks", "holder", "report"]
[camera]
focal_length_mm = 20.0
aperture_diameter_mm = 1.0
sensor_pitch_um = 5.0
doe_pitch_um = 10.0
focus_distance_m = 5.0
[optics]
kernel_px = 31
[design]
streak_arm_px = 8
[fabrication]
n_levels = 4
material = "N-BK7"
"""


def test_the_installed_command_runs_a_scene_from_any_folder(installed):
    """The wheel's ``doefab`` console script, in a folder outside the repository: the preset scene reuses the
    committed design shipped in the package; a scene of another camera is designed, exported and reported."""
    root, work, env, _, venv = installed
    doefab = str(venv / "bin" / "doefab")
    scene = work / "preset.toml"
    scene.write_text('task = "hdr"\nstages = ["design", "masks", "report"]\n[camera]\npreset = "hdr"\n')
    r = subprocess.run([doefab, "run", str(scene), "--quick", "--out", str(work / "run")],
                       cwd=work, env=env, capture_output=True, text=True)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-3000:])
    assert "reused" in r.stdout  # the committed design, from the package
    layers = sorted((work / "run" / "masks").glob("*.gds"))
    assert len(layers) >= 1 and (work / "run" / "masks" / "manifest.json").is_file()
    assert (work / "run" / "report.html").is_file()
    mine = work / "my_camera.toml"
    mine.write_text(TINY_CAMERA)
    r = subprocess.run([doefab, "run", str(mine), "--quick", "--out", str(work / "mine")],
                       cwd=work, env=env, capture_output=True, text=True)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-3000:])
    import json

    manifest = json.loads((work / "mine" / "masks" / "manifest.json").read_text())
    etch = [lay for lay in manifest["layers"] if lay["purpose"] == "etch"]
    assert manifest["n_levels"] == 4 and len(etch) == 2 and "N-BK7" in json.dumps(manifest)  # log2 4 masks
    assert (work / "mine" / "holder" / "holder.stl").is_file() and (work / "mine" / "report.html").is_file()


def test_the_license_ships_and_a_build_leaves_the_tree_clean(installed, tmp_path):
    """LICENSE (MIT, as pyproject.toml declares) is in the wheel and in the sdist, and building them from a copy
    of the checkout leaves no build/ or *.egg-info in it."""
    import tarfile
    import zipfile

    _, _, _, wheel, _ = installed
    import doefab

    # one version: the package's, which the wheel's name and metadata and CITATION.cff carry
    assert wheel.name.startswith(f"doefab-{doefab.__version__}-")
    meta = next(n for n in zipfile.ZipFile(wheel).namelist() if n.endswith(".dist-info/METADATA"))
    text = zipfile.ZipFile(wheel).read(meta).decode()
    assert f"\nVersion: {doefab.__version__}\n" in text
    # who made it, as CITATION.cff says, and where it belongs on an index
    cff_author = re.search(r'^authors:\n  - name: "([^"]+)"', (REPO / "CITATION.cff").read_text(), re.M).group(1)
    assert f"\nAuthor: {cff_author}\n" in text and "\nClassifier: Topic :: Scientific/Engineering :: Physics\n" in text
    assert re.search(rf"^version: \"?{re.escape(doefab.__version__)}\"?$", (REPO / "CITATION.cff").read_text(), re.M)
    assert "MIT License" in (REPO / "LICENSE").read_text()
    names = zipfile.ZipFile(wheel).namelist()
    lic = [n for n in names if n.endswith("licenses/LICENSE")]
    assert lic and "MIT License" in zipfile.ZipFile(wheel).read(lic[0]).decode()
    src = tmp_path / "checkout"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(REPO / name, src / name)
    for pkg in ("doefab", "holder_cad"):
        shutil.copytree(REPO / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    before = sorted(p.name for p in src.iterdir())
    code = ("from hatchling.build import build_sdist, build_wheel; import sys; "
            "print(build_sdist(sys.argv[1]), build_wheel(sys.argv[1]))")
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "dist")], check=True, cwd=src)
    assert sorted(p.name for p in src.iterdir()) == before  # no build/, no egg-info
    sdist = next((tmp_path / "dist").glob("doefab-*.tar.gz"))
    with tarfile.open(sdist) as tar:
        members = tar.getnames()
        assert any(m.endswith("/LICENSE") for m in members)
        assert any(m.endswith("doefab/designs/streak.npz") for m in members)
        assert not any("/tests/" in m or "/masks/" in m for m in members)

"""Built-in DOE substrates against published indices, their 2π heights, lookup by name and round trips through the
camera, design and mask records."""

import json

import numpy as np
import pytest

import doefab
from doefab.design.design import Design
from doefab.errors import DoefabError
from doefab.optics.materials import SUBSTRATES, fit_range_warning, material_by_name

# (wavelength µm, index) printed by an independent source, to compare to 1e-4 (the first entry is near the d line):
PRINTED = {
    # Malitson 1965 (refractiveindex.info prints n_d = 1.45846); d, F and C lines
    "fused silica": [(0.5875618, 1.45846), (0.4861327, 1.46313), (0.6562725, 1.45637)],
    # SCHOTT N-BK7 data sheet: n_d, n_F, n_C
    "N-BK7": [(0.5875618, 1.51680), (0.4861327, 1.52238), (0.6562725, 1.51432)],
    # SCHOTT Lithotec CaF2 data sheet n_d = 1.43385; Daimon & Masumura, Appl. Opt. 41, 5275 (2002), an independent
    # high-accuracy measurement, at the F and C lines (their Sellmeier formula, evaluated in formula2 below)
    "CaF2": [(0.5875618, 1.43385), (0.4861327, "daimon"), (0.6562725, "daimon")],
    # Malitson's measured ordinary index of synthetic sapphire (J. Opt. Soc. Am. 52, 1377 (1962)) at the Hg lines
    # 435.8 and 579.1 nm and the Cs line 852.1 nm, as tabulated by Valley Design's sapphire data
    "sapphire": [(0.57906, 1.76871), (0.43583, 1.78120), (0.85212, 1.75885)],
    # refractiveindex.info's Sultanova et al. (2009) entry: n² − 1 = 1.1819 λ² / (λ² − 0.011313), evaluated below
    "PMMA": [(0.5875618, "sultanova"), (0.4861327, "sultanova"), (0.6562725, "sultanova")],
}


def formula2(lam_um: float, b: tuple, c_um2: tuple) -> float:
    """refractiveindex.info "formula 2": n² − 1 = Σ B λ² / (λ² − C), C in µm² (as SCHOTT and these sources print)."""
    l2 = lam_um**2
    return float(np.sqrt(1 + sum(bi * l2 / (l2 - ci) for bi, ci in zip(b, c_um2))))


REFERENCE = {
    "daimon": lambda lam: formula2(lam, (0.443749998, 0.444930066, 0.150133991, 8.85319946),
                                   (0.00178027854, 0.00788536061, 0.0124119491, 2752.28175)),
    "sultanova": lambda lam: formula2(lam, (1.1819,), (0.011313,)),
}


def published(lam: float, n) -> float:
    return REFERENCE[n](lam) if isinstance(n, str) else n


@pytest.mark.parametrize("name", list(PRINTED))
def test_index_against_published_values(name):
    m = material_by_name(name)
    for lam, n in PRINTED[name]:
        assert float(m.index(lam * 1e-6)) == pytest.approx(published(lam, n), abs=1e-4), (name, lam)


@pytest.mark.parametrize("name", list(PRINTED))
def test_two_pi_height_from_the_published_index(name):
    """h_2π = λ / (n − 1) near the d line from the printed index (1e-4 in n is at most 2.3e-4 of h for n − 1 ≈
    0.43–0.77), and one level of an 8-level process is an eighth of it."""
    lam, n = PRINTED[name][0]
    n = published(lam, n)
    m = material_by_name(name)
    want = lam * 1e-6 / (n - 1)
    assert m.height_2pi(lam * 1e-6) == pytest.approx(want, rel=1e-4 / (n - 1) + 1e-9)
    cam = doefab.Camera(material=m, design_wavelength=lam * 1e-6)
    assert doefab.level_step(cam, 8) == pytest.approx(want / 8, rel=1e-4 / (n - 1) + 1e-9)


def test_lookup_is_case_insensitive_and_unknown_names_list_the_table():
    assert material_by_name("n-bk7") is material_by_name("N-BK7") is material_by_name("  N-bk7 ")
    assert material_by_name("caf2").name == "CaF2" and material_by_name("SAPPHIRE").name == "sapphire"
    assert material_by_name("Fused Silica") is doefab.FUSED_SILICA
    with pytest.raises(DoefabError) as exc:
        material_by_name("BK7")
    msg = str(exc.value)
    assert "unknown material 'BK7'" in msg and all(repr(n) in msg for n in SUBSTRATES) and "Sellmeier" in msg
    with pytest.raises(DoefabError, match="unknown material"):
        material_by_name(None)


@pytest.mark.parametrize("name", list(PRINTED))
def test_camera_and_design_records_round_trip_each_substrate(name, tmp_path):
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0, material=material_by_name(name))
    back = doefab.Camera.from_dict(json.loads(json.dumps(cam.to_dict())))
    assert back == cam and back.material == material_by_name(name)
    lv = np.random.default_rng(0).integers(0, 4, (100, 100)).astype(np.uint8)
    d = Design(task="grating", task_params={}, camera=cam, wavelengths=(550e-9,), depths=(5.0,),
               height=doefab.levels_to_height(lv, cam, 4), levels=lv, n_levels=4,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    d.save(tmp_path / "d")
    loaded = Design.load(tmp_path / "d")
    assert loaded.camera.material == cam.material and loaded.n_levels == 4
    assert np.array_equal(loaded.quantized_height, lv * cam.material.height_2pi(550e-9) / 4)


def test_edited_coefficients_of_a_built_in_name_are_refused():
    rec = doefab.Camera(material=material_by_name("CaF2")).to_dict()
    rec["material"]["sellmeier_b"][0] *= 1.01
    with pytest.raises(DoefabError, match="'CaF2' is a built-in material"):
        doefab.Camera.from_dict(rec)


def test_wavelengths_outside_a_published_fit_are_named():
    pmma = material_by_name("PMMA")
    assert fit_range_warning(pmma, [450e-9, 550e-9, 650e-9]) is None
    note = fit_range_warning(pmma, [400e-9, 550e-9, 1100e-9])
    assert "400 nm" in note and "1100 nm" in note and "550 nm" not in note and "Sultanova" in note
    assert fit_range_warning(doefab.Material("mine", (1.0, 0.0, 0.0), (0.1, 0.0, 0.0)), [100e-9]) is None


@pytest.mark.parametrize("name", list(PRINTED))
def test_a_mask_set_on_each_substrate_states_and_verifies_its_depths(name, tmp_path):
    """The manifest records the substrate; verification looks it up by name and re-derives every depth from it."""
    from doefab.errors import CheckFailed
    from doefab.fabrication.export import LevelMap, MaskOptions, export_masks
    from doefab.fabrication.verify import verify_mask_set

    lam, n = PRINTED[name][0]
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0, material=material_by_name(name),
                        design_wavelength=lam * 1e-6)
    lv = np.random.default_rng(1).integers(0, 4, (100, 100)).astype(np.uint8)
    export_masks(LevelMap(lv, cam, n_levels=4), tmp_path / "m", MaskOptions(use_klayout=False))
    path = tmp_path / "m" / "manifest.json"
    man = json.loads(path.read_text())
    assert man["material"]["name"] == name and man["n_levels"] == 4
    step_nm = lam * 1e3 / (published(lam, n) - 1) / 4
    assert man["level_step_nm"] == pytest.approx(step_nm, rel=1e-4 / (published(lam, n) - 1))
    assert verify_mask_set(tmp_path / "m", use_klayout=False)["levels_reproduced"]
    other = "CaF2" if name != "CaF2" else "N-BK7"
    path.write_text(json.dumps(dict(man, material=material_by_name(other).to_dict())))
    with pytest.raises(CheckFailed, match="level_step_nm"):  # another substrate needs other depths
        verify_mask_set(tmp_path / "m", use_klayout=False)

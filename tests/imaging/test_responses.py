"""Camera responses: the named published curves and a user's CSV."""

import re
import warnings

import numpy as np
import pytest

from doefab.errors import DoefabError
from doefab.imaging.responses import DEFAULT_RESPONSE, RESPONSES, response_curves, response_label, response_sha256
from doefab.imaging.sensor import Sensor, sensor_response

BANDS = np.arange(400, 701, 10) * 1e-9


@pytest.mark.parametrize("name", sorted(RESPONSES))
def test_each_named_camera_peaks_red_above_green_above_blue(name):
    """Every Bayer/Foveon camera's blue channel peaks below its green, green below red (physics of the colour
    filters / silicon depth), all three within the visible (a Foveon's middle layer peaks as late as ~590 nm)."""
    lam, curves = response_curves(name)
    peaks = lam[np.argmax(curves, axis=1)] * 1e9
    assert 560 <= peaks[0] <= 680 and 490 <= peaks[1] <= 600 and 420 <= peaks[2] <= 490, peaks
    assert peaks[0] > peaks[1] > peaks[2]


def test_the_nikon_curves_are_colour_sciences_npl_measurement():
    import colour

    lam, curves = response_curves("Nikon D5100")
    msds = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    i = list(msds.wavelengths).index(550.0)
    assert lam[i] == pytest.approx(550e-9)
    assert np.allclose(curves[:, i], msds[550.0])


def _gauss(lam_nm, mu, sigma):
    return np.exp(-0.5 * ((lam_nm - mu) / sigma) ** 2)


def test_a_csv_response_is_read_interpolated_and_normalised(tmp_path):
    """Gaussian channels written every 2 nm, read back on 10 nm bands: the response equals the Gaussians there,
    scaled so the largest channel sum over the bands is 1."""
    lam = np.arange(380, 781, 2.0)
    rows = np.column_stack([lam] + [_gauss(lam, mu, 30) for mu in (600, 540, 460)])
    path = tmp_path / "cam.csv"
    np.savetxt(path, rows, delimiter=",", header="wavelength_nm,R,G,B", comments="")
    got = sensor_response(BANDS, str(path))
    want = np.stack([_gauss(BANDS * 1e9, mu, 30) for mu in (600, 540, 460)])
    want /= want.sum(axis=1).max()
    assert np.allclose(got, want, atol=2e-4)
    assert response_label(str(path)) == "cam.csv (CSV)"


def test_a_responses_identity_is_its_content(tmp_path):
    lam = np.arange(400, 701, 5.0)
    rows = np.column_stack([lam] + [_gauss(lam, mu, 25) for mu in (610, 530, 450)])
    a, b, c = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    for p in (a, b):
        np.savetxt(p, rows, delimiter=",", header="wavelength_nm,R,G,B", comments="")
    rows[10, 2] *= 1.01
    np.savetxt(c, rows, delimiter=",", header="wavelength_nm,R,G,B", comments="")
    assert response_sha256(str(a)) == response_sha256(str(b)) != response_sha256(str(c))
    assert response_sha256("Nikon D5100") != response_sha256("Canon EOS 5D Mark II")


@pytest.mark.parametrize("text, needle", [
    ("wavelength_nm,R,G,B\n400,1,1\n500,1,1\n", "4"),  # three columns
    ("wavelength_nm,R,G,B\n400,1,1,1\n", "≥ 2 rows"),
    ("wavelength_nm,R,G,B\n400,1,nan,1\n500,1,1,1\n", "NaN"),
    ("wavelength_nm,R,G,B\n4e-7,1,1,1\n5e-7,1,1,1\n", "look like metres"),
    ("wavelength_nm,R,G,B\n500,1,1,1\n400,1,1,1\n", "increase"),
    ("wavelength_nm,R,G,B\n400,1,-1,1\n500,1,1,1\n", "≥ 0"),
    ("wavelength_nm,R,G,B\n400,1,0,1\n500,1,0,1\n", "each of R, G and B"),
    ("wavelength_nm,R,G,B\n400,a,1,1\n500,1,1,1\n", "not a readable CSV"),
    ("400,1,1,1\n500,1,1,1\n600,1,1,1\n", "is data, not a header"),
    ("\ufeff400,1,1,1\n500,1,1,1\n600,1,1,1\n", "is data, not a header"),  # a spreadsheet's byte-order mark
    ("wavelength_nm,R,G,B\n0.4,1,1,1\n0.7,1,1,1\n", "look like micrometres: write nanometres (e.g. 700)"),
])
def test_a_malformed_csv_gets_one_error_naming_the_fix(tmp_path, text, needle):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(DoefabError, match=re.escape(needle)) as exc:
        response_curves(str(p))
    assert str(p) in str(exc.value)


def test_an_unknown_name_lists_the_known_cameras():
    with pytest.raises(DoefabError, match="Nikon D5100"):
        response_curves("Canon EOS R5")


def test_bands_outside_a_response_are_refused_with_its_range():
    """31 bands 400–700 nm against a response measured on 400–680 nm: the two beyond it are named, not all 31."""
    with pytest.raises(DoefabError, match=r"wavelengths 690, 700 nm lie outside the .* 400–680 nm"):
        sensor_response(BANDS, "Sigma SD Merrill")
    assert sensor_response(BANDS[:-2], "Sigma SD Merrill").shape == (3, 29)


def test_small_negative_tails_of_a_measured_curve_read_as_zero(tmp_path):
    p = tmp_path / "tails.csv"
    p.write_text("wavelength_nm,R,G,B\n400,-0.005,0.5,1\n500,0.2,1,0.4\n600,1,0.3,-0.009\n")
    lam, curves = response_curves(str(p))
    assert curves.min() == 0.0 and curves[0, 0] == 0.0 and curves[1, 1] == 1.0


def _write(path, lam, curves, header="wavelength_nm,R,G,B", encoding="utf-8"):
    lines = [header] + [",".join(f"{v:.17g}" for v in (x, *c)) for x, c in zip(lam, np.asarray(curves).T)]
    path.write_bytes(("\n".join(lines) + "\n").encode(encoding))
    return str(path)


def test_a_csv_of_huge_values_is_normalised_without_overflow(tmp_path):
    """Sensitivities × 1e308 (any scale is relative): the same response as the file's, and no numpy warning."""
    lam = np.arange(380, 781, 5.0)
    curves = np.stack([_gauss(lam, mu, 30) for mu in (600, 540, 460)])
    plain = sensor_response(BANDS, _write(tmp_path / "a.csv", lam, curves))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        huge = sensor_response(BANDS, _write(tmp_path / "b.csv", lam, curves * 1e308))
    assert np.allclose(huge, plain, rtol=1e-6) and huge.sum(axis=1).max() == pytest.approx(1, abs=1e-6)


@pytest.mark.parametrize("level, ok", [(0.02, True), (0.005, False)])
def test_each_channel_must_see_the_bands(tmp_path, level, ok):
    """Blue peaks at 380 nm and sits at ``level`` of that peak over 400–700 nm: 2 % is seen, 0.5 % is refused
    (the threshold is 1 % of a channel's peak on average over the bands)."""
    lam = np.arange(380, 781, 5.0)
    blue = np.where(lam < 400, 1.0, level)
    path = _write(tmp_path / "cam.csv", lam, [_gauss(lam, 600, 30), _gauss(lam, 540, 30), blue])
    if ok:
        assert sensor_response(BANDS, path)[2].min() > 0
        return
    with pytest.raises(DoefabError, match=r"barely sees the bands 400–700 nm: .*B 0\.5 % .*≥ 1 %"):
        sensor_response(BANDS, path, every_channel=True)
    with pytest.raises(DoefabError, match="barely sees"):  # the sensor a scene or a flag names checks the same
        Sensor(response=path).rgb(BANDS)


@pytest.mark.parametrize("nm", [450.0, 550.0, 633.0, 656.0, 700.0])
def test_a_narrow_band_source_needs_no_channel_it_misses(nm):
    """A single line (a HeNe laser at 633 nm, the RGB task's 656 nm) is imaged by the channels that see it: the
    API does not ask blue to see red light. The channel that sees it most gives 1 (the normalisation)."""
    t = sensor_response([nm * 1e-9])
    lam, curves = response_curves(DEFAULT_RESPONSE)
    ref = np.array([np.interp(nm * 1e-9, lam, c) for c in curves])  # independent: the raw curves at that line
    assert t.shape == (3, 1) and t[:, 0].max() == pytest.approx(1.0)
    assert int(np.argmax(t[:, 0])) == int(np.argmax(ref))
    np.testing.assert_allclose(t[:, 0] / t[:, 0].max(), ref / ref.max(), rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("rows, needle", [
    ([(400, 1, 1, 1), (500, 1, 1, 1), (500, 2, 2, 2), (600, 1, 1, 1)], "line 4: wavelength 500 nm repeats line 3's"),
    ([(400, 1, 1, 1), (600, 1, 1, 1), (550, 1, 1, 1)], "line 4: wavelength 550 nm is below line 3's 600 nm"),
    ([(400, 1, 1, 1), (2500, 1, 1, 1)], "line 3: wavelength 2500 nm lies outside 200–2000 nm"),
])
def test_a_wavelength_out_of_order_is_named_by_its_line(tmp_path, rows, needle):
    p = tmp_path / "cam.csv"
    p.write_text("wavelength_nm,R,G,B\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    with pytest.raises(DoefabError, match=re.escape(needle)):
        response_curves(str(p))


def test_a_latin1_header_is_read(tmp_path):
    """A header written by a Windows tool in Latin-1 (``Wellenlänge``, ``µ``): the same curves as in UTF-8."""
    lam = np.arange(400, 701, 10.0)
    curves = np.stack([_gauss(lam, mu, 30) for mu in (600, 540, 460)])
    header = "Wellenlänge (nm),R (µA/W),G,B"
    latin = _write(tmp_path / "latin.csv", lam, curves, header, "latin-1")
    utf8 = _write(tmp_path / "utf8.csv", lam, curves, header)
    with pytest.raises(UnicodeDecodeError):
        (tmp_path / "latin.csv").read_text(encoding="utf-8")
    for a, b in zip(response_curves(latin), response_curves(utf8)):
        assert np.array_equal(a, b)

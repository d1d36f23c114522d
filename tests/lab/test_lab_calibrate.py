"""doefab calibrate's arithmetic: sub-pixel registration, a noiseless recording calibrated back to the nominal PSF,
the grid's refusals, photon transfer, and the white-wall crosstalk with its standard errors."""

import math
from pathlib import Path

import numpy as np
import pytest

import doefab
from doefab.errors import DoefabError

K = 31
SHIFT = (0.37, -0.71)  # the chief ray's offset from the frame's centre pixel (rows, columns)


def _camera():
    """A 1.08 mm aperture at 40 mm: its PSFs are sampled above Nyquist at 5.4 µm for every visible band
    (cut-off D / (λ f) < 1 / (2 p) for λ > 292 nm), so a Fourier shift resamples them exactly."""
    return doefab.Camera(aperture_diameter=1.08e-3, doe_pitch=10.8e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                         sensor_distance=40e-3, focus_distance=5.0)


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory):
    """A 3-band, 2-plane streak design (plain right half)."""
    from doefab.design.design import Design
    from doefab.tasks import get_task

    cam = _camera()
    task = get_task("streak", kernel_size=K, arm_px=6)
    task.bind(cam)
    lv = doefab.quantize_levels(task.init_height(cam, np.random.default_rng(0)), cam)
    lv[:, 50:] = 15
    d = Design(task="streak", task_params=task.params(), camera=cam, wavelengths=(656e-9, 589e-9, 486e-9),
               depths=(5.0, 2.0), height=doefab.levels_to_height(lv, cam), levels=lv,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    root = tmp_path_factory.mktemp("cal")
    d.save(root / "design")
    return root / "design"


def _psfs(design_dir, kernel, center=(0.0, 0.0)):
    """The design's L-level PSFs, computed independently of the calibration (split_aperture_psf), with the window's
    centre pixel at sensor position ``center`` (metres, x right, y up)."""
    from doefab.design.design import Design

    d = Design.load(design_dir)
    return doefab.split_aperture_psf(doefab.levels_to_height(d.levels, d.camera, d.n_levels), d.camera, d.wavelengths,
                                     d.depths, kernel, center=center)


def _write(folder, design_dir, entries, rgb=False, size=80, black=100.0):
    """Noiseless recordings (2 identical frames each, ``black`` DN added) of the PSFs computed with the chief ray at
    ``SHIFT`` from the frame's centre; ``entries``: (half, view, plane index, band index) (band ignored for rgb)."""
    from doefab.lab.frames import write_frame

    p = _camera().sensor_pitch
    big = _psfs(design_dir, size - 1, center=(-SHIFT[1] * p, SHIFT[0] * p))  # chief at centre + SHIFT
    d_wl, d_z = (656e-9, 589e-9, 486e-9), (5.0, 2.0)
    lines = ['design = "design"', f"black_level = {black}"]
    for i, (half, view, zi, bi) in enumerate(entries):
        arr = (big.coded if half == "coded" else big.uncoded)[zi].double().numpy()
        img = arr[[0, 1, 2]].transpose(1, 2, 0) if rgb else arr[bi]  # R, G, B = 656, 589, 486 nm
        frame = np.zeros((size, size) + img.shape[2:])
        frame[1:, 1:] = img  # the window's centre pixel on the frame's (size // 2, size // 2)
        for f in range(2):
            write_frame(folder / f"psf/r{i}_{f}.tiff", frame * (40000 / img.max()) + black)
        band = 'channels = "rgb"' if rgb else f"wavelength_nm = {d_wl[bi] * 1e9:g}"
        lines += ["[[psf]]", f'half = "{half}"', f'view = "{view}"', f"depth_m = {d_z[zi]}", band,
                  f'frames = ["psf/r{i}_*.tiff"]']
    (folder / "rec.toml").write_text("\n".join(lines) + "\n")
    return folder / "rec.toml"


def test_registration_recovers_a_known_subpixel_shift(design_dir):
    """The chief ray of a PSF computed at a known sub-pixel offset (the optics' own window centre, not a resampling)
    is found within 0.05 px, with photon noise too."""
    from doefab.lab.measure import register

    nominal = _psfs(design_dir, K).coded[0, 1].double().numpy()
    p = _camera().sensor_pitch
    rng = np.random.default_rng(0)
    for dy, dx in ((0.3, -0.45), (2.27, 1.61), (-0.13, 0.08)):
        win = _psfs(design_dir, 71, center=(-dx * p, dy * p)).coded[0, 1].double().numpy()
        frame = np.zeros((90, 100))
        frame[10:81, 20:91] = win  # the window's centre on frame pixel (45, 55)
        for counts in (None, 1e6):
            f = frame if counts is None else rng.poisson(frame / frame.sum() * counts) + rng.normal(0, 2, frame.shape)
            chief = register(f, nominal)
            assert np.abs(chief - (45 + dy, 55 + dx)).max() < 0.05, (dy, dx, counts, chief)


def test_noiseless_recordings_calibrate_to_the_nominal_psfs(design_dir, tmp_path):
    """Monochrome recordings of every (half, plane, band), the chief ray off the frame's centre: the calibrated
    pair is the nominal one (independently computed) to 0.5 % of its light, each shift is recovered, and the files
    carry their provenance."""
    from doefab.fabrication.levels import levels_sha256
    from doefab.lab.calibrate import calibrate
    from doefab.lab.recordings import load_recordings, recordings_sha256

    (tmp_path / "design").symlink_to(design_dir)
    entries = [(h, h, z, b) for h in ("coded", "plain") for z in (0, 1) for b in (0, 1, 2)]
    rec = load_recordings(_write(tmp_path, design_dir, entries))
    summary = calibrate(rec, tmp_path / "out")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["calibration.html", "psf_pair.npz"]
    pair = doefab.PSFPair.load(tmp_path / "out" / "psf_pair.npz")
    nominal = _psfs(design_dir, K)
    assert pair.wavelengths == (656e-9, 589e-9, 486e-9) and pair.depths == (5.0, 2.0)
    for h in ("coded", "uncoded"):
        m, n = getattr(pair, h).double(), getattr(nominal, h).double()
        rel = ((m - n).abs().sum((-1, -2)) / n.sum((-1, -2))).numpy()
        assert rel.max() < 5e-3, (h, rel)
        np.testing.assert_allclose(m.sum((-1, -2)).numpy(), n.sum((-1, -2)).numpy(), rtol=1e-5)  # the model's share
    for row in summary["recordings"]:
        np.testing.assert_allclose(row["shift_px"], SHIFT, atol=0.02)
        assert row["snr"] == math.inf and row["photons"] is None  # identical frames: no noise, no photon transfer
    prov = pair.provenance
    from doefab.design.design import Design

    assert prov["source"] == "calibrate" and prov["levels_sha256"] == levels_sha256(Design.load(design_dir).levels)
    assert prov["recordings_sha256"] == recordings_sha256(rec) and len(prov["shifts_px"]) == len(entries)
    page = (tmp_path / "out" / "calibration.html").read_text()
    assert page.count("data:image/png;base64,") >= 3 and "<script" not in page and "src=\"http" not in page
    assert summary["warnings"] == [] and "Warning:" not in page  # the halves the file states


def test_recordings_of_the_halves_swapped_are_warned_of(design_dir, tmp_path):
    """The coded half's recordings labelled plain and the plain half's coded (half and view both, so no check
    refuses them): the calibration is written, and the summary and its page say the halves look swapped."""
    from doefab.lab.calibrate import calibrate
    from doefab.lab.recordings import load_recordings

    (tmp_path / "design").symlink_to(design_dir)
    entries = [(h, h, z, b) for h in ("coded", "plain") for z in (0, 1) for b in (0, 1, 2)]
    path = _write(tmp_path, design_dir, entries)
    text = path.read_text().replace('"coded"', '"@"').replace('"plain"', '"coded"').replace('"@"', '"plain"')
    path.write_text(text)
    summary = calibrate(load_recordings(path), tmp_path / "out")
    assert len(summary["warnings"]) == 2 and all("swapped" in w for w in summary["warnings"])
    assert "the coded recordings, registered to the design's coded half, are off by" in summary["warnings"][0]
    assert "swapped" in (tmp_path / "out" / "calibration.html").read_text()


def test_psfs_mirrored_left_right_are_warned_of():
    """A plain recording of an L-shaped PSF (its mirror is no shift of itself) flipped left–right, registered as the
    calibration registers: it fits the stated template far off and the mirrored one exactly, and is warned of as
    mirrored; a recording of the stated PSF, a symmetric PSF flipped and a difference within the noise are not."""
    from doefab.lab.viewcheck import template_fits, view_warnings

    ell = np.zeros((15, 15))
    ell[4:11, 5], ell[10, 5:10] = 1.0, 1.0  # an L: a vertical bar and a foot to the right
    wide, other = [np.pad(ell, 8)], [np.pad(np.eye(15), 8)]  # the registration's wider window
    frame = np.pad(ell[:, ::-1], 20)  # the recording: the L flipped, in a larger frame
    fits = template_fits([frame], wide, other, 15)
    assert fits["stated"] > 0.5 and fits["mirrored"] == pytest.approx(0.0, abs=1e-6)
    (w,) = view_warnings([{"half": "plain", "template_fit": fits}])
    assert w.startswith("the plain recordings, registered to the design's plain half, are off by")
    assert "mirrored left–right" in w and "by 0%" in w
    assert template_fits([np.pad(ell, 20)], wide, other, 15)["stated"] == pytest.approx(0.0, abs=1e-6)
    bar = np.zeros((15, 15))
    bar[7, 3:12] = 1.0  # symmetric left–right: its mirror is itself
    flipped_bar = template_fits([np.pad(bar[:, ::-1], 20)], [np.pad(bar, 8)], other, 15)
    assert flipped_bar["stated"] == pytest.approx(0, abs=1e-6)
    assert view_warnings([{"half": "coded", "template_fit": {"stated": 0.06, "swapped": 0.02, "mirrored": 0.5}}]) == []


def test_rgb_channels_are_the_bands_in_decreasing_wavelength(design_dir, tmp_path):
    from doefab.lab.calibrate import calibrate
    from doefab.lab.recordings import load_recordings

    (tmp_path / "design").symlink_to(design_dir)
    rec = load_recordings(_write(tmp_path, design_dir, [("coded", "coded", 0, 0), ("plain", "plain", 0, 0)],
                                 rgb=True))
    calibrate(rec, tmp_path / "out")
    pair = doefab.PSFPair.load(tmp_path / "out" / "psf_pair.npz")
    nominal = _psfs(design_dir, K)
    assert pair.depths == (5.0,) and pair.wavelengths == (656e-9, 589e-9, 486e-9)
    rel = ((pair.coded.double() - nominal.coded[:1].double()).abs().sum((-1, -2)) / nominal.coded[:1].sum((-1, -2)))
    assert float(rel.max()) < 5e-3


@pytest.mark.parametrize("entries, needle", [
    ([("coded", "coded", 0, 0), ("plain", "plain", 0, 0), ("coded", "coded", 0, 1)],
     "missing plain at 5 m, 589 nm"),
    ([("coded", "coded", 0, 0), ("plain", "plain", 0, 0), ("coded", "plain", 0, 0)],
     "record it as a [[wall]]"),
    ([("coded", "coded", 0, 0), ("plain", "plain", 0, 0), ("plain", "plain", 0, 0)],
     "list all frames of one source in one recording"),
])
def test_an_incomplete_or_leaking_grid_is_refused_and_nothing_written(design_dir, tmp_path, entries, needle):
    from doefab.lab.calibrate import calibrate
    from doefab.lab.recordings import load_recordings

    (tmp_path / "design").symlink_to(design_dir)
    rec = load_recordings(_write(tmp_path, design_dir, entries))
    with pytest.raises(DoefabError) as exc:
        calibrate(rec, tmp_path / "out")
    assert needle in str(exc.value)
    assert not (tmp_path / "out").exists()


def test_photon_transfer_finds_the_gain():
    """Frames of a known gain (DN per photo-electron) and read noise: the fitted gain is the true one (the read
    noise, 40 e⁻, would bias a fit through the origin by 16 %)."""
    from doefab.lab.measure import photon_transfer

    rng = np.random.default_rng(1)
    gain, read = 0.25, 40.0
    expected = np.linspace(50, 20000, 4000)  # photo-electrons per pixel
    frames = np.stack([(rng.poisson(expected) + rng.normal(0, read, expected.shape)) * gain for _ in range(8)])
    got = photon_transfer(frames.mean(0), frames.var(0, ddof=1))
    assert abs(got / gain - 1) < 0.03
    assert photon_transfer(np.full(10, 5.0), np.ones(10)) is None  # a flat window has no slope to fit


def test_wall_crosstalk_within_three_standard_errors_which_match_the_noise():
    """Per-column ratios with a known profile, Gaussian noise σ on each view: the estimate is within 3 se, the z
    scores have unit spread, and the se is the analytic σ √((1 − α)² + α²) / (W √rows) of a ratio
    R / (L + R)."""
    from doefab.lab.measure import wall_ratios

    rng = np.random.default_rng(2)
    rows, cols, wall, sigma = 400, 96, 20000.0, 150.0
    a = 0.05 + 0.02 * np.linspace(-1, 1, cols)
    b = 0.04 - 0.01 * np.linspace(-1, 1, cols)
    ones = np.full((rows, cols), wall)
    plain_open = doefab.mix_crosstalk(ones, 0 * ones, a, b)  # (L*, R*): only the plain (left) view lit
    coded_open = doefab.mix_crosstalk(0 * ones, ones, a, b)
    noisy = [tuple(v + rng.normal(0, sigma, v.shape) for v in pair) for pair in (plain_open, coded_open)]
    a_hat, b_hat, se_a, se_b = wall_ratios(*noisy)
    z = np.concatenate([(a_hat - a) / se_a, (b_hat - b) / se_b])
    assert np.mean(np.abs(z) < 3) >= 0.99 and 0.8 < z.std() < 1.2
    for est, alpha in ((se_a, a), (se_b, b)):
        analytic = sigma * np.sqrt((1 - alpha) ** 2 + alpha ** 2) / (wall * np.sqrt(rows))
        np.testing.assert_allclose(np.median(est / analytic), 1.0, atol=0.05)


@pytest.mark.parametrize("cut", [30, 28])
def test_a_psf_cut_by_the_frames_edge_is_refused_and_nothing_written(design_dir, tmp_path, cut):
    """A point source recorded near the frame's edge: the kernel window round its chief ray reaches past the
    frame, where the design puts light. It had been read as dark, the rest rescaled to the half's share."""
    import tifffile

    from doefab.lab.calibrate import calibrate
    from doefab.lab.recordings import load_recordings

    (tmp_path / "design").symlink_to(design_dir)
    entries = [(h, h, z, b) for h in ("coded", "plain") for z in (0, 1) for b in (0, 1, 2)]
    rec_file = _write(tmp_path, design_dir, entries)
    for f in (tmp_path / "psf").glob("r0_*.tiff"):  # the first recording's chief ray 40 − cut px from the left edge
        tifffile.imwrite(f, tifffile.imread(f)[:, cut:])
    frame = rf"\[\[psf\]\] 1 .*31×31-px PSF window .*reaches past the 80×{80 - cut}-px frame"
    with pytest.raises(DoefabError, match=frame):
        calibrate(load_recordings(rec_file), tmp_path / "out")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
    for f in (tmp_path / "psf").glob("r0_*.tiff"):  # 4 px of margin more than the window needs: accepted
        tifffile.imwrite(f, np.pad(tifffile.imread(f), ((0, 0), (cut - 40 + 15 + 5, 0)), mode="edge"))
    calibrate(load_recordings(rec_file), tmp_path / "out2")


@pytest.mark.parametrize("fault", ["swapped", "sizes"])
def test_wall_pairs_that_give_no_crosstalk_are_refused_before_any_psf_work(design_dir, tmp_path, fault):
    """A [[wall]] whose coded_view and plain_view are swapped puts most of its open half's light in the view that
    half does not reach; walls of two sizes have no common columns. Both are refused naming the table and the
    fix, by the wall measurement (before the PSF recordings are worked on); a sound pair gives the sensor's
    ratios."""
    import tifffile

    from doefab.lab.calibrate import measure_walls
    from doefab.lab.recordings import load_recordings
    from doefab.lab.simulate import write_lab_recordings

    f = write_lab_recordings(tmp_path / "rec", design_dir, frames=2, dark_frames=1, wavelengths_m=[656e-9],
                             depths_m=[5.0], crosstalk=(0.05, 0.04))
    got = measure_walls(load_recordings(f))
    assert abs(float(np.median(got["alpha_lr"])) - 0.05) < 0.01
    assert abs(float(np.median(got["alpha_rl"])) - 0.04) < 0.01
    text = f.read_text()
    if fault == "swapped":  # the plain-open wall's two views exchanged
        text = text.replace('coded_view = ["wall/plain_open_coded', 'XX').replace(
            'plain_view = ["wall/plain_open_plain', 'coded_view = ["wall/plain_open_plain').replace(
            'XX', 'plain_view = ["wall/plain_open_coded')
        f.write_text(text)
        match = r"\[\[wall\]\] 2 \(half = 'plain' open\) puts most of its light .*appear swapped"
    else:  # the coded-open wall recorded 20 columns narrower, with its own dark
        for p in (tmp_path / "rec" / "wall").glob("coded_open_*.tiff"):
            tifffile.imwrite(p, tifffile.imread(p)[:, 20:])
        dark = tmp_path / "rec" / "wall" / "dark_0.tiff"
        tifffile.imwrite(tmp_path / "rec" / "wall" / "narrow_dark.tiff", tifffile.imread(dark)[:, 20:])
        f.write_text(text.replace('dark = ["wall/dark_0.tiff"]', 'dark = ["wall/narrow_dark.tiff"]', 1))
        match = r"is 62×62 px but \[\[wall\]\] 1 \(half = 'coded' open.* is 42×62 px: .*one frame size"
    with pytest.raises(DoefabError, match=match):
        measure_walls(load_recordings(f))


def test_registration_is_unbiased_where_the_design_puts_light_beyond_the_kernel(tmp_path):
    """A 64-pixel cut of the committed streak design (K = 63) puts a tenth of its coded light beyond the kernel,
    on one side more than the other. A frame of the nominal part, chief ray on a known pixel, registers there to
    1/50 px against the nominal on the registration's window; against the K × K nominal alone the tails the frame
    holds pulled the match by a quarter pixel, and the diagnosis read that as fab errors."""
    import dataclasses
    from pathlib import Path

    import torch

    from doefab.design.design import Design
    from doefab.lab.calibrate import PSFGrid, registration_size
    from doefab.lab.measure import register

    full = Design.load(Path(__file__).resolve().parents[2] / "masks" / "streak" / "design")
    n, big = 64, full.camera.doe_pixels
    lv = np.ascontiguousarray(full.levels[(big - n) // 2:(big + n) // 2, big // 8:big // 8 + n])
    lv[:, n // 2:] = 15
    cam = dataclasses.replace(full.camera, doe_pixels=n, aperture_diameter=n * full.camera.doe_pitch,
                              sensor_distance=20e-3)
    height = doefab.levels_to_height(lv, cam)

    def coded(k):
        with torch.no_grad():
            return doefab.PSFPlan(cam, [full.wavelengths[0]], [full.depths[0]], k, halves=("coded",))(height) \
                .coded[0, 0].double().numpy()

    d = Design(task="streak", task_params={}, camera=cam, wavelengths=(full.wavelengths[0],), depths=full.depths[:1],
               height=height, levels=lv, metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    wide = registration_size(d, PSFGrid(bands=[0], planes=[0], entries={}), 63)
    frame = coded(127)  # chief ray on pixel (63, 63)
    assert 1 - coded(63).sum() / frame.sum() > 0.05  # light beyond the kernel
    assert np.abs(register(frame, coded(wide), kernel=63) - 63).max() < 0.02
    assert np.abs(register(frame, coded(63)) - 63).max() > 0.1  # the K × K reference alone: biased
    # through the calibration: recordings of the nominal part, its source on the axis, read at no shift
    from doefab.lab.calibrate import measure_recordings
    from doefab.lab.recordings import load_recordings
    from doefab.lab.simulate import write_lab_recordings

    d = dataclasses.replace(d, task="streak", task_params={**full.task_params, "kernel_size": 63, "arm_px": 21})
    d.save(tmp_path / "design")
    rec = write_lab_recordings(tmp_path / "rec", tmp_path / "design", supersample=1, frames=2, dark_frames=1,
                               wall=False, photons=1e7, seed=0)
    for row in measure_recordings(load_recordings(rec)).rows:
        assert np.abs(row["shift_px"]).max() < 0.02, row["shift_px"]


@pytest.mark.parametrize("frames", [2, 3, 8])
def test_the_photon_count_states_an_error_that_covers_the_truth(frames):
    """A PSF window (a spot and a streak through it) of 0.9e6 detected photons, gain 3.83 DN/e⁻, read noise 3 e⁻,
    recorded ``frames`` times, 200 times over: the fitted gain's stated standard error matches its scatter (z
    scores of unit spread, 95 % ± 4 % within 2) and the photon count's median is within 3 % of the truth."""
    from doefab.lab.measure import photon_transfer

    rng = np.random.default_rng(frames)
    y, x = np.mgrid[:63, :63]
    shape = np.exp(-((y - 31) ** 2 + (x - 31) ** 2) / 18.0) + 0.3 * np.exp(-((y - 31) ** 2) / 2.0) * (abs(x - 31) < 25)
    e, gain = 0.9e6 * shape / shape.sum(), 3.83
    z, counts = [], []
    for _ in range(200):
        f = np.stack([(rng.poisson(e) + rng.normal(0, 3.0, e.shape)) * gain for _ in range(frames)])
        g, se = photon_transfer(f.mean(0), f.var(0, ddof=1), frames)
        z.append((g - gain) / se)
        counts.append(f.mean(0).sum() / g)
    z = np.array(z)
    assert 0.85 < z.std() < 1.15 and abs(np.mean(np.abs(z) < 2) - 0.95) < 0.04
    assert abs(np.median(counts) / 0.9e6 - 1) < 0.03


def test_a_photon_count_less_certain_than_half_is_not_stated(monkeypatch):
    """The count is the window's signal over the fitted gain, stated with the gain's relative error; a gain known
    to worse than ±50 % gives no count (and the page says why) rather than a number off by a factor."""
    import doefab.lab.calibrate as C
    from doefab.lab.framechecks import FrameSet

    rng = np.random.default_rng(0)
    y, x = np.mgrid[:31, :31]
    spot = 2e5 * np.exp(-((y - 15) ** 2 + (x - 15) ** 2) / 8.0)
    f = np.stack([rng.poisson(spot) * 2.0 for _ in range(4)])
    frames = FrameSet(f.mean(0), f.var(0, ddof=1), 4, Path("f.tiff"))
    for se, stated in ((0.1, True), (0.6, False)):
        monkeypatch.setattr(C, "photon_transfer", lambda s, v, n, se=se: (2.0, se * 2.0))
        got = C._light(frames, None, 0.0, 31)
        if stated:
            assert got["photons"] == pytest.approx(f.mean(0).sum() / 2.0, rel=1e-6)
            assert got["photons_rel_se"] == pytest.approx(se)
        else:
            assert got["photons"] is None and got["photons_rel_se"] is None


def test_the_noise_floor_is_the_half_normal_mean_of_the_background_noise():
    """A compact spot of known light on a 95 × 95 window of background noise σ: zeroing the negative pixels adds
    σ / √(2π) per background pixel (the half-normal's mean), so the floor reads 0.399 σ N / total."""
    from pathlib import Path

    from doefab.lab.framechecks import FrameSet, measure_psf

    rng = np.random.default_rng(4)
    k, sigma, total = 95, 3.0, 1e5
    spot = np.zeros((200, 200))
    spot[98:102, 98:102] = total / 16
    mean = spot + rng.normal(0, sigma, spot.shape)
    got = measure_psf(FrameSet(mean, np.full(spot.shape, 4 * sigma**2), 4, Path("f")), None, 0.0, k)
    want = sigma / math.sqrt(2 * math.pi) * (k * k - 16) / total
    assert got.noise_floor[0] == pytest.approx(want, rel=0.03)


def test_a_recording_short_only_on_its_noise_floor_is_told_the_frames_to_average():
    """Kernel SNR about 120 (passes) but a floor of about 32 %, 32 times the limit: the refusal names the frames to
    average (4 × 32² ≈ 4100), not a missing PSF; a window with no light at all is told to check the source."""
    from pathlib import Path
    from types import SimpleNamespace

    from doefab.lab.framechecks import FrameSet, _light_problems, measure_psf

    rng = np.random.default_rng(1)
    k, sigma = 95, 1.0
    spot = np.zeros((200, 200))
    spot[98:102, 98:102] = 1.2 * 100 * sigma * k / 16
    frames = FrameSet(spot + rng.normal(0, sigma, spot.shape), np.full(spot.shape, 4 * sigma**2), 4, Path("f.tiff"))
    got = measure_psf(frames, None, 0.0, k)
    assert got.kernel_snr[0] > 100 and got.noise_floor[0] > 0.3
    (text,) = _light_problems(SimpleNamespace(name="[[psf]] 1"), frames, got, k)
    frames_needed = math.ceil(4 * (got.noise_floor[0] / 0.01) ** 2)
    assert f"average more frames (about {frames_needed} at this exposure)" in text and "hold no PSF" not in text
    dark = FrameSet(rng.normal(0, 1, (200, 200)) - 0.5, np.full((200, 200), 4.0), 4, Path("g.tiff"))
    (text,) = _light_problems(SimpleNamespace(name="[[psf]] 2"), dark, measure_psf(dark, None, 0.0, k), k)
    assert "the frames hold no PSF above the noise" in text and "inf" not in text


def test_a_peak_over_pixels_that_scatter_by_less_than_a_dn_reads_a_finite_signal_to_noise():
    """Most window pixels with no scatter at all (a quiet sensor's dark region: median variance 0): the peak's SNR is
    read against the window's mean variance, not a division by nearly nothing; no light and no noise reads 0."""
    from pathlib import Path

    from doefab.lab.framechecks import FrameSet, measure_psf

    k = 15
    mean, var = np.zeros((40, 40)), np.zeros((40, 40))
    mean[20, 20], var[18:23, 18:23] = 90.0, 9.0 * 4  # one frame's variance; the mean of 4 frames scatters by 3 DN
    got = measure_psf(FrameSet(mean, var, 4, Path("f")), None, 0.0, k)
    assert got.peak_snr[0] == pytest.approx(90.0 / math.sqrt(9.0 * 25 / k**2))  # the window's mean variance
    assert got.kernel_snr[0] == pytest.approx(90.0 / math.sqrt(9.0 * 25))
    none = measure_psf(FrameSet(np.zeros((40, 40)), np.zeros((40, 40)), 4, Path("f")), None, 0.0, k)
    assert none.peak_snr[0] == none.kernel_snr[0] == 0.0


def test_a_recording_whose_clipped_noise_would_dim_the_psf_is_refused(design_dir, tmp_path):
    """Read noise high enough that the window's negative pixels, set to zero, would add several per cent of false
    light, while the kernel SNR still passes its 100: refused by the noise floor, naming the frames to average;
    a quiet recording of the same light passes."""
    from doefab.lab.framechecks import MAX_NOISE_FLOOR, MIN_KERNEL_SNR, psf_frame_problems, psf_signal
    from doefab.lab.recordings import load_recordings
    from doefab.lab.simulate import write_lab_recordings

    def recorded(read_noise_e, where):
        f = write_lab_recordings(tmp_path / where, design_dir, frames=4, dark_frames=4, wavelengths_m=[656e-9],
                                 depths_m=[5.0], photons=1e6, read_noise_e=read_noise_e, wall=False)
        rec = load_recordings(f)
        return rec, rec.psf[0]

    rec, r = recorded(250.0, "noisy")
    got = psf_signal(rec, r, K)
    assert min(got.kernel_snr) >= MIN_KERNEL_SNR and max(got.noise_floor) > 2 * MAX_NOISE_FLOOR
    (problem,) = psf_frame_problems(rec, r, K)
    assert "would add" in problem and "of false light" in problem and "average more frames" in problem
    rec, r = recorded(2.0, "quiet")
    assert psf_frame_problems(rec, r, K) == [] and max(psf_signal(rec, r, K).noise_floor) < MAX_NOISE_FLOOR

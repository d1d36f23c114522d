"""The scene report (issue 37): it opens with one paragraph in words with units built from the numbers, then the
details as a list; every figure appears once; the training curves are the networks this run used; the committed
design is starred by its level map, not by a label; captions cite only what exists."""

import csv
import json
import re
import shutil
from types import SimpleNamespace

import pytest
from matplotlib.figure import Figure

from doefab.pipeline import knobs
from doefab.pipeline.knobs import DESIGN_TABLE, REPO, committed_point, knob_plots
from doefab.pipeline.report import write_report
from doefab.pipeline.scene import load_scene

ROW = {"error": "mask overlay", "value": 0.5, "unit": "µm", "grid": 1, "metric": 0.82, "delta": -0.049,
       "network_delta": {"nominal_psf": {"psnr_highlight": -1.2, "psnr": -0.3},
                         "measured_psf": {"psnr_highlight": -0.6, "psnr": -0.1}}}
TOLERANCE = {
    "task": "hdr", "stop": "the DOE's 8.64 mm baffle is narrower than the lens's 27.50 mm entrance pupil",
    "warnings": [], "level": "network", "design": "d", "seed": 0, "n_levels": 16,
    "budget": {"spec": {"hdr": {"psf_metric_min": 0.8, "psnr_highlight_db_min": 28.0}}},
    "nominal": {"psf": {"psf_metric": 0.869}, "network": {"nominal_psf": {"psnr_highlight": 29.9, "psnr": 45.8}}},
    "spec": {"psf": "psf_metric ≥ 0.8", "network": "psnr_highlight ≥ 28"},
    "summary": {"metric": {"mean": 0.822, "ci95": [0.805, 0.839]},
                "yield": {"level": "psf", "value": 2 / 3, "ci95": [0.39, 0.86], "n": 12},
                "network": {"nominal_psf": {
                    "metrics": {"psnr_highlight": {"mean": 29.123, "ci95": [28.5, 29.7]},
                                "psnr": {"mean": 45.2, "ci95": [45.0, 45.4]}},
                    "yield": {"value": 0.75, "ci95": [0.468, 0.911], "n": 12}}}},
    "tornado": [ROW], "grid": {"fixed": True, "monte_carlo_grid": 1, "kinds": {}},
}
# a report of stages without a resolved scene: its design settings alone
SETTINGS = SimpleNamespace(settings={"design_task": "streak", "wavelengths_m": [656e-9], "depths_m": [5.0],
                                     "kernel_px": 95})


def _png(path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    fig.savefig(path, dpi=50)
    plt.close(fig)


def _run_folder(tmp_path, design: str = "streak") -> tuple:
    """A finished run's folder as the report reads it: the committed design, a tolerance study, its figures."""
    from doefab.design.committed import committed_dir

    out = tmp_path / "run"
    (out / "design").mkdir(parents=True)
    for f in ("design.json", "levels.npy"):
        shutil.copyfile(committed_dir(design) / f, out / "design" / f)
    (out / "tolerance").mkdir()
    (out / "tolerance" / "tolerance.json").write_text(json.dumps(TOLERANCE))
    for f in ("tornado.png", "yield_vs_n.png", "delivered.png"):
        _png(out / "tolerance" / f)
    done = {"design": {"status": "reused", "metric": {"name": "m", "quantized": 0.87, "quantized_worst": 0.84}},
            "reconstruction": {"status": "reused", "weights": "shipped",
                               "rows": {"proposed": {"psnr_highlight": 29.9, "psnr": 45.8}}},
            "tolerance": {"status": "ran", "why": "12 Monte Carlo parts through the network"}}
    return out, done


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A run folder with its report written."""
    out, done = _run_folder(tmp_path_factory.mktemp("report"))
    write_report(out, load_scene(REPO / "scenes" / "hdr.toml"), done, SETTINGS)
    return out


@pytest.fixture
def saved(monkeypatch):
    """{file name: figure} of every matplotlib figure saved while the test runs."""
    figs, save = {}, Figure.savefig

    def record(self, fname, *args, **kwargs):
        figs[str(fname).rsplit("/", 1)[-1]] = self
        return save(self, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", record)
    return figs


def _summary(md: str) -> list[str]:
    return md.split("## Summary\n\n", 1)[1].split("\n## ", 1)[0].split("\n\n")


def test_the_report_opens_with_one_paragraph_in_words_with_units(written):
    md = (written / "report.md").read_text()
    lead = _summary(md)[0]
    assert lead.startswith("This part delivers 29.12 dB highlight PSNR, the mean over 12 simulated fabricated parts")
    assert "28.50–29.70 dB" in lead and "the error-free part 29.90 dB" in lead
    assert "75 % of the parts (95 % Wilson interval 47–91 %) meet the spec (highlight PSNR ≥ 28.00 dB)" in lead
    assert "mask overlay (0.5 µm at the budget's 1σ costs 1.20 dB of highlight PSNR)" in lead
    assert "psnr_highlight" not in lead and "\n" not in lead and not lead.startswith("- ")
    assert all(line.startswith("- ") for line in _summary(md)[1].splitlines())  # then the details, a list
    html = (written / "report.html").read_text()
    section = html.split('<section id="summary"><h2>Summary</h2>', 1)[1]
    assert section.startswith("<p>This part delivers 29.12 dB highlight PSNR") and "<ul><li>" in section
    assert not re.search(r"<p>\s*- ", html) and "**" not in html


def test_without_a_tolerance_study_the_opening_says_what_the_error_free_part_delivers(tmp_path):
    out, done = _run_folder(tmp_path)
    shutil.rmtree(out / "tolerance")
    del done["tolerance"]
    write_report(out, load_scene(REPO / "scenes" / "hdr.toml"), done, SETTINGS)
    lead = _summary((out / "report.md").read_text())[0]
    assert lead.startswith("The error-free part delivers 29.90 dB highlight PSNR") and "no tolerance study" in lead


def test_every_figure_appears_once(written):
    md = (written / "report.md").read_text()
    shown = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert "tolerance/yield_vs_n.png" in shown and len(shown) == len(set(shown)), shown
    html = (written / "report.html").read_text()
    assert html.count('src="tolerance/yield_vs_n.png"') == 1


def test_the_training_curves_are_those_of_the_networks_this_run_trained(tmp_path, saved):
    out, done = _run_folder(tmp_path)
    weights = out / "reconstruction" / "weights"
    weights.mkdir(parents=True)
    mine = [31.5, 32.25, 33.0]
    for v in ("proposed", "coded_only", "uncoded_only"):
        with open(weights / f"hdr_{v}_history.csv", "w", newline="") as f:
            csv.writer(f).writerows([["step", "wall_time_s", "loss", "val_psnr"]]
                                    + [[i + 1, 60.0 * (i + 1), 0.1, y] for i, y in enumerate(mine)])
    done["reconstruction"] = {"status": "ran", "weights": "train", "rows": {}}
    (out / "report_files").mkdir()
    _, _, caption = knobs._training_knob(out, load_scene(REPO / "scenes" / "hdr.toml"), done, out / "report_files")
    assert caption.startswith("this run's networks' validation curves")
    ax = saved["knob_training.png"].axes[0]
    assert list(ax.get_lines()[0].get_ydata()) == mine and ax.get_ylabel() == "PSNR (dB) on the validation split"


def test_without_networks_no_training_curves_are_shown(tmp_path):
    out, done = _run_folder(tmp_path)
    done["reconstruction"] = {"status": "skipped", "why": "no network for this sensor"}
    assert knobs._training_knob(out, load_scene(REPO / "scenes" / "hdr.toml"), done, out) is None


def _chosen(fig) -> list:
    return [t for t in fig.axes[0].texts if t.get_text().startswith("chosen")]


@pytest.mark.skipif(not (REPO / DESIGN_TABLE).is_file(), reason="the design benchmark's table is not in this tree")
def test_the_committed_design_is_starred_by_its_level_map(tmp_path, saved):
    import numpy as np

    out, done = _run_folder(tmp_path)
    scene = load_scene(REPO / "scenes" / "hdr.toml")
    knobs._design_knob(out, scene, out)
    meta = json.loads((out / "design" / "design.json").read_text())
    (star,) = _chosen(saved["knob_design.png"])
    assert star.xy == pytest.approx((meta["extra"]["wall_time_s"], meta["metrics"]["quantized"]))
    # another level map is not the committed design, whatever it is called
    lv = np.load(out / "design" / "levels.npy")
    lv[0, 0] = (int(lv[0, 0]) + 1) % 16
    meta["levels_sha256"] = __import__("hashlib").sha256(lv.tobytes()).hexdigest()
    (out / "design" / "design.json").write_text(json.dumps(meta))
    assert committed_point("streak", out / "design")[0] is None
    knobs._design_knob(out, scene, out)
    assert _chosen(saved["knob_design.png"]) == []


def _citations(text: str) -> list[tuple[str, str | None]]:
    """(file, section or None) of every document a caption cites: `path` ("section") or README, section."""
    cited = [(p, s or None) for p, s in re.findall(r"`([\w./-]+\.\w+)`(?: \(\"([^\"]+)\"\))?", text)]
    return cited + [("README.md", s) for s in re.findall(r"README, ([^;.)]+)", text)]


@pytest.mark.skipif(not (REPO / DESIGN_TABLE).is_file(), reason="the design benchmark's table is not in this tree")
def test_captions_cite_only_files_and_sections_that_exist(tmp_path):
    out, done = _run_folder(tmp_path, "half-ring")
    figs = knob_plots(out, load_scene(REPO / "scenes" / "depth.toml"), done)
    caption = next(c for t, _, c in figs if t == "Optimiser iterations")
    assert "ring law" in caption  # the half-ring's note, which cites a page
    cited = [c for _, _, cap in figs for c in _citations(cap)]
    assert any(section for _, section in cited)
    for path, section in cited:
        assert (REPO / path).is_file(), path
        if section:
            assert re.search(rf"^#+ {re.escape(section)}\s*$", (REPO / path).read_text(), re.M), (path, section)


@pytest.mark.parametrize("name", ["hdr", "hyperspectral", "depth"])
def test_the_dynamic_range_row_speaks_of_the_scenes_own_task(name):
    from doefab.pipeline.report import system_table
    from doefab.pipeline.system import resolve

    (row,) = [r for r in system_table(resolve(load_scene(REPO / "scenes" / f"{name}.toml")))
              if r[0] == "capture dynamic range"]
    assert ("HDR task recovers highlights" in row[2]) == (name == "hdr")
    assert {"hdr": "HDR", "hyperspectral": "spectral", "depth": "depth"}[name] in row[2]


def test_the_reconstruction_table_is_shown_beside_the_tolerance_judges_error_free_part(tmp_path):
    """Row 12 of issue 38: the table's proposed highlight PSNR (read on 4 test scenes through 2 fabricated parts)
    sits beside the tolerance judge's error-free part and its parts' mean (8 test scenes each), and the report says
    why they differ: the fabricated parts and the scenes. With the same scenes and clean captures no reason is left
    but the depth planes of a clean table."""
    out, done = _run_folder(tmp_path)
    tol = json.loads((out / "tolerance" / "tolerance.json").read_text())
    tol["network_judge"] = {"images": 8, "size": 256, "split": "test"}
    (out / "tolerance" / "tolerance.json").write_text(json.dumps(tol))
    (out / "reconstruction").mkdir()
    (out / "reconstruction" / "metrics.json").write_text(json.dumps(
        {"images": 4, "size_px": 256, "split": "test", "conditions": {"name": "honest", "parts": 2}}))
    write_report(out, load_scene(REPO / "scenes" / "hdr.toml"), done, SETTINGS)
    section = (out / "report.md").read_text().split("## Reconstruction\n", 1)[1].split("\n## ", 1)[0]
    assert "the table's proposed highlight PSNR, 29.90 dB, is read on 4 test scenes of 256² px captured through 2 " \
           "fabricated parts" in section
    assert "each part on 8 test scenes of 256² px: the error-free part 29.90 dB, the mean of its 12 simulated " \
           "parts 29.12 dB" in section
    assert "They differ because the table's captures are made through 2 fabricated parts" in section
    assert "the scenes differ (4 test scenes of 256² px against 8 test scenes of 256² px" in section
    html = (out / "report.html").read_text().split('<section id="reconstruction">', 1)[1].split("</section>", 1)[0]
    assert "the error-free part 29.90 dB" in html
    from doefab.pipeline.report import beside_tolerance

    (out / "reconstruction" / "metrics.json").write_text(json.dumps(
        {"images": 8, "size_px": 256, "split": "test", "conditions": {"name": "clean"}}))
    (text,) = [t for _, t in beside_tolerance(out, "hdr", done["reconstruction"]["rows"])]
    assert "(clean captures)" in text and "the scenes differ" not in text and "fabricated parts drawn" not in text
    assert text.endswith("the table's captures are clean (the nominal model's own: depth on the network's own planes).")


def test_report_text_renders_and_says_what_is_a_benchmark(tmp_path):
    from doefab.pipeline.report import BENCHMARK, write_report
    from doefab.pipeline.scene import load_scene

    scene = load_scene(REPO / "scenes" / "hyperspectral.toml")
    from types import SimpleNamespace

    res = SimpleNamespace(settings={"design_task": "grating", "wavelengths_m": [5e-7] * 31, "depths_m": [5.0],
                                    "kernel_px": 191})  # a report of stages without a resolved scene
    write_report(tmp_path, scene, {"reconstruction": {"status": "reused", "weights": "shipped", "rows": {}}}, res)
    page = (tmp_path / "report.html").read_text()
    assert "`" not in page and f"<code>{scene.path}</code>" in page
    assert page.count(BENCHMARK) >= 3  # the PSF and design benchmark captions, and the section's note
    assert "not in this run" in page  # the shipped weights' training curves


def test_the_tornado_table_gives_each_delivered_change_its_scene_noise(tmp_path):
    """A tornado row judged through the network carries its change's 95 % interval over the judge's scenes: the
    report's table prints it beside the change and says what it means; a loss inside it ranks nothing (the
    opening names the PSF metric's largest loss instead)."""
    from doefab.tolerance.reporttext import NOISE_NOTE

    out, done = _run_folder(tmp_path)
    noisy = {**ROW, "network_delta_ci95": {"nominal_psf": {"psnr_highlight": 1.5, "psnr": 0.4},
                                           "measured_psf": {"psnr_highlight": 0.7, "psnr": None}}}
    (out / "tolerance" / "tolerance.json").write_text(json.dumps({**TOLERANCE, "tornado": [noisy]}))
    write_report(out, load_scene(REPO / "scenes" / "hdr.toml"), done, SETTINGS)
    md = (out / "report.md").read_text()
    assert "highlight PSNR -1.2 ± 1.5 dB, PSNR -0.3 ± 0.4 dB" in md and "PSNR -0.1 dB" in md
    assert NOISE_NOTE in md
    lead = _summary(md)[0]
    assert "mask overlay (0.5 µm at the budget's 1σ costs 0.049 of the PSF metric; no error judged through the " \
           "network lowered what the part delivers by more than the judge's scene noise)" in lead


def test_the_files_to_send_name_the_run_folder_where_it_is_now(tmp_path):
    """A run folder that was moved (or copied) after its masks stage names its own masks and holder folders, not
    the paths recorded where the run was: as links relative to the report, which hold wherever the folder goes."""
    from doefab.pipeline.summary import summary_items

    out = tmp_path / "moved_run"
    (out / "masks").mkdir(parents=True)
    (out / "masks" / "grating.gds").write_bytes(b"")
    done = {"masks": {"status": "ran", "mask_set": str(tmp_path / "old_place" / "masks")},
            "holder": {"status": "ran", "files": ["holder.stl"]}}
    items = summary_items(out, done, "hyperspectral")[1][1]
    assert ("to the fab: [masks/](masks/) ([grating.gds](masks/grating.gds), [manifest.json](masks/manifest.json), "
            "[README.txt](masks/README.txt))") in items  # links relative to the report, which sits beside them
    assert "to the printer: [holder/](holder/) ([holder.stl](holder/holder.stl))" in items
    assert not any("old_place" in i or str(tmp_path) in i for i in items)
    from doefab.pipeline.report import html_text

    # a name with a space and parentheses: the target percent-encoded, a link in Markdown and in HTML alike
    done["holder"]["files"] = ["holder (v2).stl"]
    line = next(i for i in summary_items(out, done, "hyperspectral")[1][1] if "to the printer" in i)
    assert "[holder (v2).stl](holder/holder%20%28v2%29.stl)" in line
    assert '<a href="holder/holder%20%28v2%29.stl">holder (v2).stl</a>' in html_text(line)


def test_markdown_tables_keep_their_columns_and_figures_their_captions():
    """A cell holding ``|`` (a metric named with absolute bars) split its row: the depth report's reconstruction
    table rendered as a paragraph. Captions were alt text only, which renderers do not show."""
    from doefab.pipeline.report import _render

    rows = [["a", "b |x| c", "d"], ["1", "mean |log10| error", "3"]]
    md, _ = _render([("S", [("table", rows), ("img", "f.png", "a `code` caption, not this run")])])
    table = [ln for ln in md if ln.startswith("|")]
    assert all(len(re.split(r"(?<!\\)\|", ln)) == 5 for ln in table), table  # 3 cells between 4 bars
    assert "*a `code` caption, not this run*" in md and "![a code caption, not this run](f.png)" in md


def test_an_installation_without_the_benchmark_tables_says_why_their_figures_are_missing(tmp_path, monkeypatch):
    """A wheel carries no ``benchmarks/``: the two benchmark figures are replaced by a line naming the table and
    where it is, which the report prints where the figure would stand (they were dropped without a word)."""
    out, done = _run_folder(tmp_path / "run")
    monkeypatch.setattr(knobs, "REPO", tmp_path / "installed")  # a tree without benchmarks/results
    figs = {t: (f, c) for t, f, c in knob_plots(out, load_scene(REPO / "scenes" / "hdr.toml"), done)}
    for title, table in (("PSF sampling", "benchmarks/results/psf_error_vs_time.csv"),
                         ("Optimiser iterations", DESIGN_TABLE)):
        f, caption = figs[title]
        assert f is None and f"`{table}`" in caption and "not in this installation" in caption
    write_report(out, load_scene(REPO / "scenes" / "hdr.toml"), done, SETTINGS)
    text = (out / "report.md").read_text()
    assert "PSF sampling: not shown: its table, `benchmarks/results/psf_error_vs_time.csv` (a repository-wide" in text
    assert "<p>PSF sampling: not shown" in (out / "report.html").read_text()

"""The report's "error against run time" figures: one per stage that has a knob, each with this run's setting
marked and a caption saying whether the plot is this run's or a repository-wide benchmark.

- PSF sampling and route: the benchmark's table, the route every run uses starred;
- optimiser iterations: this run's design history, or (a reused committed design) the design benchmark with the
  committed design starred, found by its level map's SHA-256;
- training time: the validation curves of the networks this run used (its own when it trained them);
- Monte Carlo samples: this run's running yield.
"""

from __future__ import annotations

import csv
from pathlib import Path

from doefab.io import read_json
from doefab.plotting import save_figure

__all__ = ["knob_plots", "committed_point", "BENCHMARK", "REPO"]

REPO = Path(__file__).resolve().parents[2]
BENCHMARK = "repository-wide benchmark, not this run"
DESIGN_TABLE = "benchmarks/results/design_metric_vs_time.md"
DEPTH_DESIGNS = "`docs/results/design.md` (\"Depth designs, chosen by the network\")"


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def knob_plots(out: Path, scene, done: dict) -> list[tuple[str, str, str]]:
    """(title, file, caption) of every error-against-run-time plot, each with the chosen setting marked (file None:
    a benchmark's figure this installation cannot draw, the caption saying why)."""
    rdir = out / "report_files"
    rdir.mkdir(exist_ok=True)
    figs = [_psf_knob(rdir), _design_knob(out, scene, rdir), _training_knob(out, scene, done, rdir)]
    if (out / "tolerance" / "yield_vs_n.png").is_file():
        figs.append(("Monte Carlo samples", "tolerance/yield_vs_n.png",
                     "this run's running yield and its 95 % interval; the chosen N is the right end"))
    return [f for f in figs if f is not None]


def _absent(title: str, table: str):
    """A benchmark figure whose table this installation lacks (a wheel carries no ``benchmarks/``): (title, None,
    why), which the report prints as a line where the figure would stand."""
    return title, None, (f"not shown: its table, `{table}` (a {BENCHMARK}), is in doefab's source repository, "
                         f"not in this installation")


def _psf_knob(rdir: Path):
    table = "benchmarks/results/psf_error_vs_time.csv"
    if not (REPO / table).is_file():
        return _absent("PSF sampling", table)
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.8), layout="constrained")
    with open(REPO / table, newline="") as f:
        records = list(csv.DictReader(f))
    for r in records:
        try:
            t, e = float(r["time_s"]), float(r["rel_l2"])
        except (KeyError, ValueError):
            continue
        chosen = r.get("route", "").startswith("spectral (default)")
        ax.scatter(t, e, s=60 if chosen else 20, marker="*" if chosen else "o", color="red" if chosen else "C0")
        if chosen:
            ax.annotate("chosen: spectral, q = 1, float32", (t, e), textcoords="offset points", xytext=(8, 8),
                        fontsize=8, color="red")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time for a 31-band coded PSF (s, 2-core CPU)")
    ax.set_ylabel("relative L2 error of the PSF")
    ax.set_title(f"PSF sampling and route ({BENCHMARK})", fontsize=9)
    save_figure(fig, rdir / "knob_psf.png", dpi=100)
    return ("PSF sampling", "report_files/knob_psf.png",
            f"{BENCHMARK}: the 31-band hyperspectral case measured by `benchmarks/psf_error_vs_time.py` "
            f"(`benchmarks/results/psf_error_vs_time.csv`); the star marks the setting every run uses")


def _design_knob(out: Path, scene, rdir: Path):
    hist = out / "design" / "history.csv"
    plt = _plt()
    if hist.is_file():
        with open(hist, newline="") as f:
            rows = list(csv.DictReader(f))
        fig, ax = plt.subplots(figsize=(6, 3.8), layout="constrained")
        t = [float(r["wall_time_s"]) for r in rows]
        m = [float(r["metric"]) for r in rows]
        ax.plot(t, m)
        ax.plot(t[-1], m[-1], "r*", ms=12, label=f"chosen: {len(rows)} iterations")
        ax.set_xlabel("optimisation wall time (s)")
        ax.set_ylabel("task metric (fraction of coded light in band)")
        ax.legend(fontsize=8)
        save_figure(fig, rdir / "knob_design.png", dpi=100)
        return "Optimiser iterations", "report_files/knob_design.png", "this run's design history"
    from doefab.applications import application

    if not (REPO / DESIGN_TABLE).is_file():
        return _absent("Optimiser iterations", DESIGN_TABLE)
    rows = _benchmark_designs(application(scene.task).design_task)
    if not rows:
        return None
    point, note = committed_point(application(scene.task).design_task, out / "design")
    fig, ax = plt.subplots(figsize=(6, 3.8), layout="constrained")
    right = max(r[2] for r in rows + ([("", point[0], point[1])] if point else []))
    for name, metric, secs in rows:
        if point and (round(point[0], 4), round(point[1])) == (metric, round(secs)):
            continue  # the committed design's own row: starred below
        far = secs > 0.6 * right
        ax.scatter(secs, metric, s=25, color="C0")
        ax.annotate(name, (secs, metric), textcoords="offset points", xytext=(-6 if far else 6, 4),
                    ha="right" if far else "left", fontsize=7)
    if point:
        ax.scatter(point[1], point[0], s=140, marker="*", color="red", zorder=3)
        ax.annotate("chosen: the committed design (this run's)", (point[1], point[0]), textcoords="offset points",
                    xytext=(-6, -12), ha="right", fontsize=7, color="red")
    ax.set_xlabel("design wall time (s, 2-core CPU)")
    ax.set_ylabel("quantized task metric (full grid)")
    ax.set_title(f"optimiser and grid against run time ({BENCHMARK})", fontsize=9)
    save_figure(fig, rdir / "knob_design.png", dpi=100)
    return ("Optimiser iterations", "report_files/knob_design.png",
            f"{BENCHMARK}: " + ("this run reused the committed design (starred)" if point else
                                "this run's design is none of these runs" if (out / "design" / "design.json").is_file()
                                else "this run made no design") + "; the design runs measured by "
            f"`benchmarks/design_metric_vs_time.py` and `benchmarks/nlopt_optimizers.py` (table in "
            f"`{DESIGN_TABLE}`)" + note)


def _benchmark_designs(design_name: str) -> list[tuple[str, float, float]]:
    """(run, 16-level metric, wall time in s) of the design benchmark's rows for one design task."""
    table = REPO / DESIGN_TABLE
    rows = []
    if table.is_file():
        for line in table.read_text().splitlines():
            cells = [c.strip() for c in line.strip("|").split("|")]
            if len(cells) >= 4 and cells[0] == design_name:
                try:
                    rows.append((cells[1], float(cells[2]), float(cells[3])))
                except ValueError:
                    continue
    return rows


def committed_point(design_name: str, design_dir: Path) -> tuple[tuple[float, float] | None, str]:
    """(16-level metric, wall time in s) of the committed design when the design in ``design_dir`` is it (the
    same level map: equal ``levels_sha256``), else None; and a caption note when its metric is measured against
    other targets than the benchmark's pixel-wise runs (a radial design with another ring law)."""
    from doefab.design.committed import committed_dir
    from doefab.errors import DoefabError

    try:
        meta = read_json(committed_dir(design_name) / "design.json")
        mine = read_json(Path(design_dir) / "design.json")
    except (OSError, ValueError, DoefabError):
        return None, ""
    if mine.get("levels_sha256") != meta.get("levels_sha256"):
        return None, ""
    point = (float(meta["metrics"]["quantized"]), float(meta.get("extra", {}).get("wall_time_s") or float("nan")))
    cfg = meta.get("extra", {}).get("config", {})
    law = meta.get("task_params", {}).get("ring_law")
    if cfg.get("parameterization", "pixel") == "pixel" or not law:
        return point, ""
    from doefab.tasks.halfring import HalfRingTask

    return point, (f"; the committed design is {cfg['parameterization']} with the {law} ring law, its metric measured "
                   f"against that law's targets (the pixel-wise runs': the {HalfRingTask.ring_law} law's): "
                   f"{DEPTH_DESIGNS}")


def _training_knob(out: Path, scene, done: dict, rdir: Path):
    """The validation curves of the networks this run evaluated: those it trained (``reconstruction/weights``)
    or the shipped ones; none when the reconstruction stage used no network."""
    from doefab.pipeline.scenekeys import weights_mode
    from doefab.reconstruction.metrics import metric_label
    from doefab.reconstruction.weights import history_path

    rc = done.get("reconstruction") or {}
    if rc.get("status") in (None, "skipped"):
        return None
    trained = weights_mode(rc.get("weights")).trains
    folder = out / "reconstruction" / "weights" if trained else None
    curves = [(v, history_path(scene.task, v, folder)) for v in ("proposed", "coded_only", "uncoded_only")]
    if not any(p.is_file() for _, p in curves):
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.8), layout="constrained")
    metric = None
    for v, p in curves:
        if not p.is_file():
            continue
        with open(p, newline="") as f:
            rows = list(csv.reader(f))
        metric = rows[0][3].removeprefix("val_")
        pts = [(float(r[1]) / 60, float(r[3])) for r in rows[1:] if r[3] not in ("nan", "")]
        ax.plot([a for a, _ in pts], [b for _, b in pts], label=v.replace("_", "-"))
        if v == "proposed" and pts:
            ax.plot(pts[-1][0], pts[-1][1], "r*", ms=12,
                    label=f"{'trained here' if trained else 'shipped'}: {pts[-1][0]:.1f} min")
    ax.set_xlabel("training wall time (minutes, 2-core CPU)")
    ax.set_ylabel(f"{metric_label(scene.task, metric)} on the validation split")
    ax.legend(fontsize=8)
    save_figure(fig, rdir / "knob_training.png", dpi=100)
    return ("Training time", "report_files/knob_training.png",
            "this run's networks' validation curves, recorded while this run trained them (`reconstruction/weights`)"
            if trained else "the shipped networks' validation curves, recorded when they were trained (`doefab "
            "train`), not in this run; this run evaluated those networks")

"""Results pages from ``benchmarks/results/``: the tables and figures the benchmark scripts write, never copied.

For each measurement below, ``write_pages`` writes ``docs/_generated/results/<name>.md``: the command that
measured it (taken from the script's docstring), the files it wrote and their content — Markdown tables as they
are, figures as images, JSON records as tables. A results page includes those files under its own headings and
says in its own words what was measured. Problems are returned as warnings (errors under ``-W``): a script
whose docstring names no command, an output that is missing or that its script does not write, and a file in
``benchmarks/results/`` (``.md`` or ``.png``) that no page shows.
"""

from __future__ import annotations

import ast
import json
import re
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
OUT = ROOT / "docs" / "_generated" / "results"


@dataclass(frozen=True)
class Measurement:
    """name: the generated file.  script: the benchmark script (None: a doefab command wrote it).
    outputs: files relative to the repository root.  before: commands that make the script's inputs.
    command: the command when no script's docstring holds it.  note: one line on where the file comes from."""

    name: str
    script: str | None
    outputs: tuple[str, ...]
    before: tuple[str, ...] = ()
    command: str | None = None
    note: str = ""
    json_table: str | None = None  # a renderer below for JSON outputs


R = "benchmarks/results/"
MEASUREMENTS = (
    Measurement("psf_error_vs_time", "benchmarks/psf_error_vs_time.py",
                (R + "psf_error_vs_time.md", R + "psf_error_vs_time.png")),
    Measurement("psf_floor", "benchmarks/psf_floor.py", (R + "psf_floor.md",)),
    Measurement("psf_defocus_staircase", "benchmarks/psf_defocus_staircase.py", (R + "psf_defocus_staircase.md",)),
    Measurement("start_metrics", "benchmarks/start_metrics.py", (R + "start_metrics.md",)),
    Measurement("design_metric_vs_time", "benchmarks/design_metric_vs_time.py",
                (R + "design_metric_vs_time.md", R + "design_metric_vs_time.png")),
    Measurement("design_time_half-ring", "benchmarks/design_time.py", (R + "design_time_half-ring.md",)),
    Measurement("nlopt_optimizers", "benchmarks/nlopt_optimizers.py", (R + "nlopt_optimizers.md",)),
    Measurement("fab_regularizer", "benchmarks/fab_regularizer.py", (R + "fab_regularizer.md",)),
    Measurement("depth_candidates", "benchmarks/depth_candidates_report.py",
                (R + "depth_candidates.md", "docs/depth_candidates_psfs.png", "docs/depth_winner_psfs_all_planes.png"),
                before=("bash scripts/depth_candidates.sh",)),
    Measurement("mask_export", "benchmarks/mask_export.py", (R + "mask_export.md",)),
    Measurement("holder_timing", "benchmarks/holder_timing.py", (R + "holder_timing.md",)),
    Measurement("reconstruction_tables", "benchmarks/reconstruction_tables.py", (R + "reconstruction_tables.md",),
                before=("bash scripts/train_shipped.sh 1000 STAGING hdr",
                        "bash scripts/train_shipped.sh 1000 STAGING depth",
                        "bash scripts/train_shipped.sh 200 STAGING hyperspectral",
                        "# the shipped weights' records hold the commands that made them")),
    Measurement("reconstruction_tables_final", None, (R + "reconstruction_tables_final.md", R + "final_split_reads.md"),
                before=("for t in hdr hyperspectral depth; do",
                        "  .venv/bin/python -m doefab evaluate --task $t --split final --images 12 --size 256 "
                        "--out out/final/$t",
                        "  .venv/bin/python -m doefab evaluate --task $t --split final --images 12 --size 256 "
                        "--clean --out out/final/${t}_clean",
                        "done"),
                command=".venv/bin/python benchmarks/reconstruction_tables.py --final out/final",
                note="the final test set's tables and the ledger of its reads, each row as its evaluation logged "
                     "it"),
    Measurement("test_split_reads", None, (R + "test_split_reads.md",),
                command="git log -p -- 'benchmarks/results/evaluate_*.json'",
                note="the ledger of the test split's reads, a row for each commit that changes "
                     "`benchmarks/results/evaluate_*.json` (the rows before the ledger from this history)"),
    Measurement("reconstruction_speed", "benchmarks/reconstruction_speed.py", (R + "reconstruction_speed.md",)),
    Measurement("training_curves", "benchmarks/training_curves.py", (R + "training_curves.png",)),
    Measurement("hdr_solve", "benchmarks/hdr_solve.py", (R + "hdr_solve.json",), json_table="hdr_solve"),
    Measurement("hdr_loss_pilot", "benchmarks/hdr_loss_pilot.py", (R + "hdr_loss_pilot.md",)),
    Measurement("depth_training_crop", "benchmarks/depth_training_pilot.py", (R + "depth_training_crop.md",)),
    Measurement("depth_error_sources", "benchmarks/depth_error_sources.py", (R + "depth_error_sources.md",)),
    Measurement("render_planes", "benchmarks/render_planes.py", (R + "render_planes.md",)),
    Measurement("hdr_real_images", "benchmarks/hdr_real_images.py", (R + "hdr_real_images.json",),
                json_table="hdr_real_images"),
    Measurement("tolerance_studies", "benchmarks/tolerance_studies.py", (R + "tolerance_studies.md",)),
    Measurement("delivered_yield_streak", None, (R + "delivered_yield_streak.md",),
                command=".venv/bin/python benchmarks/delivered_yield.py streak --parts 24 --scenes 8 --size 256 "
                        "--name delivered_yield_streak"),
    Measurement("delivered_yield_halfring", None, (R + "delivered_yield_halfring.md",),
                command=".venv/bin/python benchmarks/delivered_yield.py half-ring --parts 24 --scenes 8 --size 256 "
                        "--name delivered_yield_halfring"),
    Measurement("delivered_yield_grating", None, (R + "delivered_yield_grating.md",),
                command=".venv/bin/python benchmarks/delivered_yield.py grating --parts 24 --scenes 8 --size 256 "
                        "--workers 1 --name delivered_yield_grating"),
    *(Measurement(f"tolerance_{d}", "benchmarks/tolerance_studies.py", (R + f"tolerance_{d}/report.md",),
                  note=f"the report.md of `doefab tolerance --design masks/{d} …` and its figures, kept in "
                       f"`benchmarks/results/tolerance_{d}/`") for d in ("streak", "grating", "halfring")),
    Measurement("tolerance_grid", "benchmarks/tolerance_grid.py", (R + "tolerance_grid.md",)),
    Measurement("run_time", "benchmarks/run_time.py", (R + "run_time.md",)),
    Measurement("run_time_side_by_side", None, (R + "run_time_side_by_side.md",),
                command=".venv/bin/python benchmarks/run_time.py --jobs 2"),
    Measurement("illuminant_search", "benchmarks/illuminant_search.py", (R + "illuminant_search.md",)),
    Measurement("spectra_nearest_pairs", "benchmarks/spectra_nearest_pairs.py", (R + "spectra_nearest_pairs.md",)),
    Measurement("spectra_training_content", "benchmarks/spectra_training_content.py",
                (R + "spectra_training_content.md",)),
    Measurement("tolerance_speed", "benchmarks/tolerance_speed.py", (R + "tolerance_speed.md",)),
    Measurement("judge_profile", "benchmarks/judge_profile.py", (R + "judge_profile.md",)),
    Measurement("pair_reuse", "benchmarks/pair_reuse.py", (R + "pair_reuse.md",)),
    Measurement("depth_gap", "benchmarks/depth_gap.py", (R + "depth_gap.md",)),
    Measurement("depth_planes", "benchmarks/depth_planes.py", (R + "depth_planes.md",)),
    Measurement("depth_recipes", "benchmarks/depth_recipes.py", (R + "depth_recipes.md",),
                before=("doefab train --task depth --variant proposed --steps 1000 --minutes 600 "
                        "--out out/recipes/A",)),
    Measurement("training_plateau", "benchmarks/training_plateau.py",
                (R + "training_plateau_hdr.md", R + "training_plateau_hyperspectral.md"),
                before=("# each candidate: its command is in its weights record, named under its table",
                        "doefab train --task T --variant V --steps N --minutes 600 --weights-dir DIR --out RUN")),
    Measurement("hdr_highlight_bias", "benchmarks/hdr_highlight_bias.py", (R + "hdr_highlight_bias.md",)),
    Measurement("judge_rounding", "benchmarks/judge_rounding.py", (R + "judge_rounding.md",)),
    Measurement("diagnose_coverage", "benchmarks/diagnose_coverage.py", (R + "diagnose_coverage.md",)),
    Measurement("diagnose_memory", "benchmarks/diagnose_memory.py", (R + "diagnose_memory.md",)),
    Measurement("diagnose_coverage_seed43", None, (R + "diagnose_coverage_seed43/diagnose_coverage.md",),
                command=".venv/bin/python benchmarks/diagnose_coverage.py --block 64 --parts 20 --seed 43 "
                        "--results benchmarks/results/diagnose_coverage_seed43"),
    Measurement("diagnose_coverage_starts4", None, (R + "diagnose_coverage_starts4/diagnose_coverage.md",),
                command=".venv/bin/python benchmarks/diagnose_coverage.py --block 64 --parts 20 --starts 4 "
                        "--results benchmarks/results/diagnose_coverage_starts4"),
    Measurement("diagnose_coverage_no_roughness", None, (R + "diagnose_coverage_no_roughness/diagnose_coverage.md",),
                command=".venv/bin/python benchmarks/diagnose_coverage.py --block 64 --parts 20 --roughness-nm 0 "
                        "--results benchmarks/results/diagnose_coverage_no_roughness"),
    Measurement("measured_pair", "benchmarks/measured_pair.py", (R + "measured_pair.md",)),
    Measurement("reconstruct_memory", "benchmarks/reconstruct_memory.py", (R + "reconstruct_memory.md",)),
    Measurement("swapped_views", "benchmarks/swapped_views.py", (R + "swapped_views.md",)),
    Measurement("real_validation", "benchmarks/real_validation.py", (R + "real_validation.md",)),
    Measurement("hdr_fewer_iters", "benchmarks/hdr_fewer_iters.py", (R + "hdr_fewer_iters.md",)),
    Measurement("gpu_table", None, (R + "gpu_table.md",), command="bash benchmarks/gpu_run.sh",
                note="CPU against GPU on one machine with a CUDA GPU: the CUDA tests, then "
                     "`benchmarks/gpu_table.py` one workload at a time"),
)

COMMAND = re.compile(r"\.venv/bin/python benchmarks/\w+\.py(?:[ \t]+(?![(])[^\s(;]+)*")


def script_command(script: Path) -> str | None:
    """The run command a benchmark script's docstring names (``.venv/bin/python benchmarks/NAME.py ...``)."""
    doc = ast.get_docstring(ast.parse(script.read_text())) or ""
    own = [m.group(0).rstrip(" .,") for m in COMMAND.finditer(doc) if f"benchmarks/{script.name}" in m.group(0)]
    return own[0] if own else None


def demote_headings(text: str, top: int = 3) -> str:
    """Shift Markdown headings so the file's highest one becomes level ``top`` (it sits under a page's own)."""
    levels = [len(m.group(1)) for m in re.finditer(r"^(#+) ", text, flags=re.M)]
    if not levels:
        return text
    shift = top - min(levels)
    return re.sub(r"^(#+) ", lambda m: "#" * (len(m.group(1)) + shift) + " ", text, flags=re.M)


# paragraphs of prose in a results file that tell how a number came about rather than what it is
HISTORY = re.compile(r"\b(replaced|re-measure\w*|swallowed|session|issue)\b", re.I)
# a number in a table that Python printed as "nan" ("nan", "+nan", "nan dB", "nan / 0.5"), not as a reader reads a
# missing number ("—" and why); a word that begins with "nan" is not one
NAN_CELL = re.compile(r"^\|.*(?<![\w.])[+-]?nan\b", re.I | re.M)


def markdown_body(path: Path, problems: list[str]) -> str:
    """A results Markdown file for inclusion: headings demoted, figures that are not kept beside it dropped,
    prose about earlier versions left out."""
    out = []
    text = path.read_text()
    if NAN_CELL.search(text):
        problems.append(f"results: {path.name} prints 'nan' in a table: write '—' and "
                        "say why the number is missing")
    for para in text.strip().split("\n\n"):
        if not para.lstrip().startswith("|") and HISTORY.search(para):
            continue
        images = re.findall(r"!\[([^\]]*)\]\(([^)]+)\)", para)
        if images and all(not (path.parent / src).is_file() for _, src in images):
            names = ", ".join(f"`{src}`" for _, src in images)
            out.append(f"*(The command also writes {names} beside the report; those figures are not kept in "
                       f"`benchmarks/results/`.)*")
            continue
        for alt, src in images:
            para = para.replace(f"]({src})", f"](/../{(path.parent / src).relative_to(ROOT).as_posix()})")
        if not para.lstrip().startswith(("|", "#", "![")):
            para = "\n\n".join(para.splitlines())  # the scripts write one statement per line
        out.append(para)
    return demote_headings("\n\n".join(out))


def _fmt(v, digits: int = 4) -> str:
    return f"{v:.{digits}g}" if isinstance(v, float) else str(v)


def table_hdr_solve(data: dict) -> str:
    head = (f"Mean over {data['images']} {data['split']} scenes of {data['size_px']}² px; PSNR with peak "
            f"{data['psnr_peak']}; highlight columns over the pixels the plain capture clips.\n\n")
    rows = ["| captures | CGLS iterations | bounded iterations × restarts | RMSE | PSNR (dB) | highlight RMSE | "
            "highlight PSNR (dB) | seconds per image |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in data["rows"]:
        bound = f"{r['bound_iters']} × {r['bound_rounds']}" if r["bound_iters"] else "—"
        rows.append(f"| {r['views']} | {r['iters']} | {bound} | {_fmt(r['rmse'])} | {_fmt(r['psnr'])} | "
                    f"{_fmt(r['rmse_highlight'])} | {_fmt(r['psnr_highlight'])} | {_fmt(r['seconds_per_image'], 2)} |")
    return head + "\n".join(rows)


def table_hdr_real_images(data: dict) -> str:
    variants = [k for k in next(iter(data["rows"].values())) if k != "clipped_percent"]
    head = (f"Each photograph at {data['size_px']}² px through the committed streak design; PSNR with peak "
            f"{data['psnr_peak']}; each cell: RMSE / highlight PSNR (dB); weights: {data['weights_dir']}.\n\n")
    rows = ["| image | plain capture clipped (%) | " + " | ".join(v.replace("_", "-") for v in variants) + " |",
            "| --- | --- | " + " | ".join("---" for _ in variants) + " |"]
    for image, rec in data["rows"].items():
        cells = [f"{_fmt(rec[v]['rmse'], 3)} / {_fmt(rec[v]['psnr_highlight'], 4)}" for v in variants]
        rows.append(f"| {image} | {_fmt(rec['clipped_percent'], 2)} | " + " | ".join(cells) + " |")
    return head + "\n".join(rows)


JSON_TABLES = {"hdr_solve": table_hdr_solve, "hdr_real_images": table_hdr_real_images}


def render(m: Measurement, problems: list[str]) -> str:
    """The generated Markdown of one measurement."""
    lines = [f"<!-- generated by docs/_ext/doefab_results.py from {', '.join(m.outputs)}: do not edit -->", ""]
    command = m.command
    if m.script is not None:
        script = ROOT / m.script
        if not script.is_file():
            problems.append(f"results: {m.script} does not exist")
            return ""
        command = script_command(script)
        if command is None:
            problems.append(f"results: the docstring of {m.script} names no '.venv/bin/python {m.script} ...' command")
            return ""
        source = script.read_text()
        for o in m.outputs:
            if Path(o).name not in source:
                problems.append(f"results: {o} is shown as written by {m.script}, which never names it")
    lines += ["Measured with:", "", "```bash", *m.before, command, "```", ""]
    wrote = ", ".join(f"`{o}`" for o in m.outputs)
    lines += [f"*{m.note or ('which writes ' + wrote)}.*", ""]
    for o in m.outputs:
        path = ROOT / o
        if not path.is_file():
            problems.append(f"results: {o} is missing (run: {command})")
            continue
        if path.suffix == ".md":
            lines += [markdown_body(path, problems), ""]
        elif path.suffix == ".png":
            lines += [f"![{path.stem.replace('_', ' ')}](/../{o})", ""]
        elif path.suffix == ".json" and m.json_table:
            lines += [JSON_TABLES[m.json_table](json.loads(path.read_text())), ""]
        else:
            problems.append(f"results: no way to show {o}")
    return "\n".join(lines)


HEADING = re.compile(r"^#+ (.+?)\s*$", re.M)
INCLUDE = re.compile(r"_generated/results/([\w.-]+)\.md")


def drop_repeated_headings(texts: dict[str, str]) -> dict[str, str]:
    """Each generated file without its title (its first heading) where its page already shows that title: as a
    heading of its own (the section the file is included under) or as the title of a file it includes before (the
    variants of one measurement share a title). Headings inside a file stay: under different titles the same
    sub-heading names a section of each."""
    out = dict(texts)
    for page in sorted((ROOT / "docs" / "results").glob("*.md")):
        src = page.read_text()
        seen = {h.strip() for h in HEADING.findall(src)}
        for name in INCLUDE.findall(src):
            if name not in out:
                continue
            lines = out[name].split("\n")
            first = next((i for i, line in enumerate(lines) if HEADING.match(line)), None)
            if first is None:
                continue
            title = HEADING.match(lines[first]).group(1).strip()
            if title in seen:
                out[name] = "\n".join(lines[:first] + lines[first + 1:])
            seen.add(title)
    return out


def write_pages() -> list[str]:
    """Write every measurement's Markdown; returns the problems found."""
    problems: list[str] = []
    OUT.mkdir(parents=True, exist_ok=True)
    texts = drop_repeated_headings({m.name: render(m, problems) for m in MEASUREMENTS})
    for m in MEASUREMENTS:
        text = texts[m.name]
        path = OUT / f"{m.name}.md"
        if not path.is_file() or path.read_text() != text:
            path.write_text(text)
    pages = "".join(p.read_text() for p in sorted((ROOT / "docs" / "results").glob("*.md")))
    problems += [f"results: _generated/results/{m.name}.md is included by no page of docs/results/"
                 for m in MEASUREMENTS if f"_generated/results/{m.name}.md" not in pages]
    shown = {o for m in MEASUREMENTS for o in m.outputs}
    for f in sorted(RESULTS.iterdir()):
        rel = R + f.name
        if f.suffix in (".md", ".png") and rel not in shown:
            problems.append(f"results: {rel} is on no results page: add it to MEASUREMENTS in "
                            f"docs/_ext/doefab_results.py and include it in a page of docs/results/")
    return problems

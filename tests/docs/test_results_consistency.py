"""The published Tables 1–3 are the shipped networks' evaluation, to every printed digit: the tables file
(shown on the results pages) is rebuilt from the evaluate_<task>.json it is made from, the README's table rounds
those numbers as printed, each evaluation names the shipped weights it scored by their SHA-256 and the one torch
thread it ran on, and every change to the evaluations is a read of the test split with its row in the ledger.
The README's table is the final test set's: read once per task, capture condition and set of networks, each read in
its ledger."""

import hashlib
import importlib.util
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
TASKS = ("hdr", "hyperspectral", "depth")
EVALUATIONS = "benchmarks/results/evaluate_*.json"
NOT_FINAL = ":(exclude)benchmarks/results/evaluate_final_*.json"  # the final set's reads: their own ledger
LEDGER = "benchmarks/results/test_split_reads.md"
FINAL_LEDGER = RESULTS / "final_split_reads.md"
# the README's reconstruction table: (task cell, metric cell) -> (task, light group or None, metric keys)
README_ROWS = {("HDR", "highlight PSNR (dB)"): ("hdr", None, ("psnr_highlight",)),
               ("HDR", "PSNR (dB)"): ("hdr", None, ("psnr",)),
               ("spectra", "PSNR (dB)"): ("hyperspectral", None, ("psnr",)),
               ("spectra", "SAM (rad)"): ("hyperspectral", None, ("sam",)),
               ("spectra, light in the network's library", "PSNR (dB) / SAM (rad)"):
                   ("hyperspectral", "in-library", ("psnr", "sam")),
               ("spectra, light outside it", "PSNR (dB) / SAM (rad)"):
                   ("hyperspectral", "out-of-library", ("psnr", "sam")),
               ("depth", "MAE (m)"): ("depth", None, ("mae",)),
               ("depth", "δ<1.25"): ("depth", None, ("delta125",))}
README_COLUMNS = (("proposed", ""), ("coded_only", ""), ("uncoded_only", ""), ("proposed", "_clean"))


def _evaluation(task: str, kind: str = "", split: str = "test") -> dict:
    prefix = "evaluate_final_" if split == "final" else "evaluate_"
    return json.loads((RESULTS / f"{prefix}{task}{kind}.json").read_text())


def _tables_module():
    spec = importlib.util.spec_from_file_location("reconstruction_tables",
                                                  ROOT / "benchmarks" / "reconstruction_tables.py")
    tables = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tables)
    return tables


def test_the_tables_file_is_the_evaluations_to_every_printed_digit():
    tables = _tables_module()
    assert tables.tables_markdown(RESULTS) == (RESULTS / "reconstruction_tables.md").read_text()
    final = tables.tables_markdown(RESULTS, "evaluate_final_")
    assert final == (RESULTS / "reconstruction_tables_final.md").read_text()
    assert final.count("of the final split") == len(TASKS)


@pytest.mark.parametrize("split", ["test", "final"])
@pytest.mark.parametrize("kind", ["", "_clean"])
@pytest.mark.parametrize("task", TASKS)
def test_each_evaluation_scored_the_shipped_weights_on_one_thread(task, kind, split):
    ev = _evaluation(task, kind, split)
    assert "threads" in ev, (f"evaluate_{task}{kind}.json records no thread count: evaluate again as "
                             f"benchmarks/reconstruction_tables.py says")
    assert ev["split"] == split and ev["conditions"]["name"] == ("clean" if kind else "honest")
    assert ev["threads"] == 1 and {"torch", "numpy", "scipy", "scikit-image"} <= set(ev["versions"])
    assert set(ev["weights"]) == {"proposed", "coded_only", "uncoded_only"}
    for variant, w in ev["weights"].items():
        shipped = (ROOT / "doefab" / "weights" / f"{task}_{variant}.pt").read_bytes()
        assert w["sha256"] == hashlib.sha256(shipped).hexdigest(), (task, variant)


def _readme_rows() -> dict:
    """{(task cell, metric cell): [cell text of each variant column]} of the README's reconstruction table."""
    text = (ROOT / "README.md").read_text()
    section = text.split("**Reconstruction**", 1)[1].split("\n\n**", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 6 and cells[0] not in ("task", "---"):
            rows[tuple(cells[:2])] = cells[2:]
    return rows


def test_the_readme_table_is_the_evaluations_to_every_printed_digit():
    rows = _readme_rows()
    assert set(rows) <= set(README_ROWS), f"rows this test cannot tie to an evaluation: {set(rows) - set(README_ROWS)}"
    assert {k for k, (_, light, _) in README_ROWS.items() if light is None} <= set(rows)
    for (label, metric), cells in rows.items():
        task, light, keys = README_ROWS[(label, metric)]
        for (variant, kind), cell in zip(README_COLUMNS, cells):
            ev = _evaluation(task, kind, "final")
            means = ev["by_light"][light][variant] if light else ev["rows"][variant]
            printed = [p.strip().strip("*") for p in cell.split("/")]
            assert len(printed) == len(keys), (label, metric, cell)
            for key, p in zip(keys, printed):
                digits = len(p.split(".")[1]) if "." in p else 0
                assert f"{means[key]:.{digits}f}" == p, (label, metric, variant + kind, key, means[key], p)


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True).stdout


def _ledger_rows(text: str) -> list[str]:
    return re.findall(r"^\| [^|\n]*\| ([^|\n]*) \|", text, flags=re.M)


def test_every_change_to_the_evaluations_has_its_row_in_the_test_split_ledger():
    """A commit that changed evaluate_*.json is listed by its hash or adds a row to the ledger itself; evaluations
    changed in the working tree need a row added there too."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: the history the ledger follows is not here")
    listed = [c.strip() for c in _ledger_rows((ROOT / LEDGER).read_text())]
    missing = []
    for commit in _git("log", "--format=%H", "--", EVALUATIONS, NOT_FINAL).split():
        if any(c and commit.startswith(c) for c in listed if re.fullmatch(r"[0-9a-f]{7,40}", c)):
            continue
        added = _git("show", "--format=", commit, "--", LEDGER)
        if not re.search(r"^\+\| ", added, flags=re.M):
            missing.append(commit[:7])
    assert not missing, f"reads of the test split with no row in {LEDGER}: {missing}"
    if _git("status", "--porcelain", "--", EVALUATIONS, NOT_FINAL).strip():
        try:
            before = _git("show", f"HEAD:{LEDGER}")
        except subprocess.CalledProcessError:  # the ledger is new
            before = ""
        assert len(_ledger_rows((ROOT / LEDGER).read_text())) > len(_ledger_rows(before)), \
            f"evaluate_*.json changed: add the read's row to {LEDGER}"


def _final_reads() -> list[list[str]]:
    """The cells of every row of the final test set's ledger."""
    return [[c.strip() for c in line.strip().strip("|").split("|")]
            for line in FINAL_LEDGER.read_text().splitlines() if line.startswith("| 20")]


def test_the_final_test_set_was_read_once_per_task_condition_and_networks_and_published_as_read():
    """One logged read of the final set per task, capture condition and set of networks (a task's networks
    retrained after a decision on validation data are read once more, after it), and the published evaluation is
    the latest read of its task and condition: its task, condition, code, scene count and every network's weights
    (SHA-256 prefix) as logged."""
    reads = _final_reads()
    seen = [(task, "clean" if "clean captures" in what else "honest",
             frozenset(re.findall(r"\w+ \(weights [0-9a-f]{12}\)", what.split("; ", 1)[1])))
            for _, _, task, what in reads]  # the networks read, in whatever order the row lists them
    assert len(set(seen)) == len(seen), seen  # no set of networks read twice
    assert {(t, c) for t, c, _ in seen} == {(t, c) for t in TASKS for c in ("honest", "clean")}, seen
    latest = {}
    for row in sorted(reads):  # by date
        latest[(row[2], "_clean" if "clean captures" in row[3] else "")] = row
    for (task, kind), (when, code, _, what) in latest.items():
        ev = _evaluation(task, kind, "final")
        assert code == ev["code"] and what.startswith(f"{ev['images']} scenes of {ev['size_px']}² px"), (task, kind)
        for variant, w in ev["weights"].items():
            assert f"{variant} (weights {w['sha256'][:12]})" in what, (task, kind, variant)


def test_the_final_evaluations_came_after_every_decision_taken_on_the_test_split():
    """The final set is read after every decision: its reads are dated no earlier than the last row of the test
    split's ledger that decided something; a later read of the test split is an analysis that chose nothing."""
    text = (ROOT / LEDGER).read_text()
    rows = re.findall(r"^\| (\d{4}-\d{2}-\d{2}) \|.*\| ([^|]*?) *\|\s*$", text, flags=re.M)
    assert len(rows) == len(re.findall(r"^\| \d{4}-", text, flags=re.M))  # every dated row read
    first_final = min(when[:10] for when, *_ in _final_reads())
    later = [(when, decided) for when, decided in rows if when > first_final]
    assert all(re.fullmatch(r"(an analysis; )?nothing (chosen|recorded)", decided) for _, decided in later), later
    decided = [when for when, d in rows if not re.search(r"nothing (chosen|recorded)", d)]
    assert all(when[:10] >= max(decided) for when, *_ in _final_reads())
    assert any(when <= first_final for when, _ in rows)  # the ledger was read: rows before the final reads


def test_the_readme_measured_data_line_is_real_validation_json():
    """The README's measured-data numbers round the committed ``real_validation.json`` (proposed / coded only /
    uncoded only on each task's primary metric, SAM, and the proposed depth δ<1.25)."""
    import json
    import re

    runs = json.loads((ROOT / "benchmarks" / "results" / "real_validation.json").read_text())
    text = " ".join((ROOT / "README.md").read_text().split())
    line = text[text.index("**On measured data**"):]
    variants = ("proposed", "coded_only", "uncoded_only")
    for label, task, key, digits in (("highlight PSNR", "hdr", "psnr_highlight", 1),
                                     ("SAM", "hyperspectral", "sam", 2), ("MAE", "depth", "mae", 2)):
        got = re.search(re.escape(label) + r" ([\d.]+) / ([\d.]+) / ([\d.]+)", line).groups()
        want = [f"{runs[task]['real']['rows'][v][key]:.{digits}f}" for v in variants]
        assert list(got) == want, (label, got, want)
    d = re.search(r"δ<1.25 ([\d.]+) \(final set", line).group(1)
    assert d == f"{runs['depth']['real']['rows']['proposed']['delta125']:.2f}"


def _table(text: str, first_header: str) -> dict:
    """{first cell: cells} of the Markdown table whose header starts with ``first_header``."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {first_header} |"))
    rows = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        rows[cells[0]] = cells
    return rows


def test_the_readme_tolerance_table_is_the_tolerance_studies_file():
    """Each design's row of the README's tolerance table holds the tolerance studies' numbers as that file prints
    them: nominal metric, mean and interval, yield and interval at the spec, and the largest single loss."""
    studies = _table((RESULTS / "tolerance_studies.md").read_text(), "design | nominal PSF metric")
    readme = _table((ROOT / "README.md").read_text(), "design | nominal PSF metric")
    assert set(studies) == {"streak", "grating", "half-ring"}
    for design, (_, nominal, mean, spec, yld, losses) in studies.items():
        row = readme[design]
        assert row[1:4] == [nominal, mean, f"{yld} at {spec}"], design
        assert row[4] == losses.split(";")[0].strip(), design


def _paired(task: str, key: str, against: str, sign: float = 1.0) -> tuple:
    """(mean, low, high, better, n) of proposed − ``against`` per scene on the final set (× ``sign``), with the 95 %
    Student-t interval, computed here from the scene scores."""
    import numpy as np
    from scipy import stats

    per = _evaluation(task, "", "final")["per_image"]["rows"]
    d = sign * np.array([p[key] - a[key] for p, a in zip(per["proposed"], per[against])])
    half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
    return d.mean(), d.mean() - half, d.mean() + half, int((d > 0).sum()), len(d)


def test_the_readme_claims_are_the_final_sets_numbers():
    """The margins, intervals, scene counts and ratios the README states against the paper's claims, recomputed
    from the final set's scene scores."""
    text = " ".join((ROOT / "README.md").read_text().split()).replace("−", "-")
    claims = text[text.index("Against the paper's claims, on the final set"):]
    m, lo, hi, better, n = _paired("hdr", "psnr_highlight", "uncoded_only")
    assert f"highlight PSNR {m:+.1f} dB over uncoded only" in claims
    assert f"interval over scenes {lo:+.1f} to {hi:+.1f} dB (better on {better} of {n} scenes)" in claims
    m, lo, hi, _, _ = _paired("hyperspectral", "psnr", "uncoded_only")
    assert f"PSNR {m:+.1f} dB over uncoded only ({lo:+.1f} to {hi:+.1f} dB)" in claims
    depth = _evaluation("depth", "", "final")["rows"]
    ratios = [depth["proposed"]["mae"] / depth[v]["mae"] for v in ("coded_only", "uncoded_only")]
    assert f"MAE {ratios[0]:.2f}× coded only, {ratios[1]:.2f}× uncoded only" in claims
    clean = _evaluation("depth", "_clean", "final")["rows"]["proposed"]["delta125"]
    assert f"δ<1.25 = {depth['proposed']['delta125']:.2f}, below the 0.9 target (clean {clean:.2f})" in claims

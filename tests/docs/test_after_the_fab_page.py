"""The "After the fab" guide page states the recordings file's keys and the thresholds that the checks and the
diagnosis apply: a key or a threshold changed in the code and not on the page fails here."""

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PAGE = REPO / "docs" / "guide" / "after-the-fab.md"


def schema_rows(text: str) -> set[tuple[str, str]]:
    """(table, key) of every row of the page's key table: ``top``, ``psf`` or ``wall`` and the key."""
    out = set()
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 4 or not cells[0].startswith("`"):
            continue
        where = re.findall(r"\[\[(\w+)\]\]", cells[1]) or (["top"] if cells[1] == "top" else [])
        out |= {(w, k) for w in where for k in re.findall(r"`([a-z_]+)`", cells[0])}
    return out


def test_the_page_lists_every_key_of_the_recordings_file_and_no_other():
    from doefab.lab import recordings

    tables = {"psf", "wall"}
    code = ({("top", k) for k in recordings._TOP if k not in tables} | {("psf", k) for k in recordings._PSF}
            | {("wall", k) for k in recordings._WALL})
    assert schema_rows(PAGE.read_text(encoding="utf-8")) == code


def test_the_page_states_the_thresholds_the_code_applies():
    from doefab.lab import diagnose, framechecks, partmodel, recordings

    text = " ".join(PAGE.read_text(encoding="utf-8").split())
    stated = {
        "kernel SNR": f"must be at least {framechecks.MIN_KERNEL_SNR:g}",
        "peak SNR": f"brightest pixel over the window's median pixel noise, must be at least "
                    f"{framechecks.MIN_PEAK_SNR:g}",
        "saturation": f"reaches {framechecks.SATURATION * 100:g} % of the file's full scale",
        "band": f"within {recordings.WAVELENGTH_TOL_M * 1e9:g} nm of a design band",
        "plane": f"within {recordings.DEPTH_TOL * 100:g} % of one of the design's",
        "bound": f"±{partmodel.BOUND:g} budget σ",
        "correlation": f"|r| ≥ {diagnose.MAX_CORRELATION:g}",
        "etch precision": f"etch depth scale when its σ is above {partmodel.ETCH_PRECISION * 100:g} % (its 2σ "
                          f"interval wider than ±{2 * partmodel.ETCH_PRECISION * 100:g} %",
        "rival fits": f"misfit lies within {diagnose.MIRROR_CHI2:g} s² of the best's (2σ of the noise) plus twice the rms",
    }
    missing = {name: phrase for name, phrase in stated.items() if phrase not in text}
    assert not missing, f"the page does not state: {missing}"
    assert diagnose.MAX_SIGMA == 0.5 and "not below half the budget's σ" in text


def test_schema_rows_reads_a_table_row_per_key_and_table():
    rows = schema_rows("| `dark` | `[[psf]]`, `[[wall]]` | frames | none |\n| `design` | top | folder | none |\n"
                       "| key | where | value | default |\n")
    assert rows == {("psf", "dark"), ("wall", "dark"), ("top", "design")}

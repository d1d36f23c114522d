"""``doefab doctor``: a folder is named as a folder; --out replaces only its own report."""

import json

from cli_helpers import REPO, run_cli


def test_a_folder_is_named_as_a_folder(tmp_path, capsys):
    (tmp_path / "somedir.toml").mkdir()
    rc, _, err = run_cli(["doctor", tmp_path / "somedir.toml"], capsys)
    assert rc == 2 and "is a folder" in err and "not found" not in err


def test_doctor_out_replaces_only_its_own_report(tmp_path, capsys):
    """``doctor --out F`` writes F; a rerun replaces its own report; a file of the user's is never replaced."""
    f = tmp_path / "d.json"
    for _ in range(2):
        rc, _, _ = run_cli(["doctor", REPO / "scenes" / "hdr.toml", "--no-precision", "--out", f], capsys)
        assert rc == 0 and json.loads(f.read_text())["written_by"] == "doefab doctor"
    mine = tmp_path / "notes.txt"
    mine.write_text("my notes")
    rc, _, err = run_cli(["doctor", REPO / "scenes" / "hdr.toml", "--no-precision", "--out", mine], capsys)
    assert rc == 2 and "never replaces" in err and mine.read_text() == "my notes"


def test_doctor_says_a_reused_design_costs_no_time_and_no_timing_leaves_the_row_out(tmp_path, capsys):
    f = tmp_path / "d.json"
    rc, out, _ = run_cli(["doctor", REPO / "scenes" / "hdr.toml", "--no-precision", "--out", f], capsys)
    row = next(r for r in json.loads(f.read_text())["system"] if r["quantity"] == "design stage's run time")
    assert rc == 0 and row["value"] == 0.0 and "reused" in row["meaning"] and "design stage's run time" in out
    rc, out, _ = run_cli(["doctor", REPO / "scenes" / "hdr.toml", "--no-precision", "--no-timing"], capsys)
    assert rc == 0 and "run time" not in out


def test_doctors_json_is_strict_json_with_unbounded_margins_written_as_inf(tmp_path, capsys):
    """The HDR scene's source-phase check at a plane wave has no bound to approach (margin ∞): the report writes it
    "inf", which strict readers (a browser's JSON.parse) take, where Python's json would write Infinity."""
    f = tmp_path / "d.json"
    rc, _, _ = run_cli(["doctor", REPO / "scenes" / "hdr.toml", "--no-precision", "--no-timing", "--out", f], capsys)

    def refuse(c):
        raise ValueError(f"non-standard JSON constant {c}")

    rows = json.loads(f.read_text(), parse_constant=refuse)["checks"]
    assert rc == 0 and "inf" in [r["margin"] for r in rows]

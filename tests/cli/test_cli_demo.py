"""``doefab demo``: a folder of the user's is never taken for its output."""

from cli_helpers import run_cli


def test_a_users_summary_json_is_not_a_demo_output(tmp_path, capsys):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "summary.json").write_text("{}\n")
    rc, _, err = run_cli(["demo", "--out", tmp_path / "d"], capsys)
    assert rc == 2 and "not a doefab demo output" in err
    assert [p.name for p in (tmp_path / "d").iterdir()] == ["summary.json"]

"""The grid study says what it runs and how far it is."""


def test_the_grid_study_shows_its_progress(grating_design, capsys):
    """The grid study (a scene without ``supersample``) prints what it runs and how far it is, one error kind at a
    time, and finishes the line at n of n."""
    from doefab.design.design import Design
    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.grid import grid_study
    from doefab.tolerance.judge import PSFJudge

    design = Design.load(grating_design(96, 31))
    budget = load_budget(None)
    rec = grid_study(PSFJudge(design, 1), budget, block=64, progress=True)
    err = capsys.readouterr().err
    n = len(rec["kinds"])
    assert n >= 2 and "grid study" in err and f"{n}/{n}" in err and f"0/{n}" in err
    grid_study(PSFJudge(design, 1), budget, block=64, progress=False)
    assert "grid study" not in capsys.readouterr().err

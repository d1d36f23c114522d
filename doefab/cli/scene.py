"""``doefab scene new --task T --out FILE``: a commented scene file with every key, its unit, range and
default (values for a 35 mm f/4 camera with 3.76 µm pixels on an APS-C sensor to edit); ``doefab scene keys``:
the key table. Check a scene with ``doefab doctor FILE`` and run it with ``doefab run FILE``."""

from __future__ import annotations

from doefab.applications import APPLICATIONS


def register(sub) -> None:
    p = sub.add_parser("scene", help="write a scene template, or list every key with its unit",
                       description=__doc__)
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    new = actions.add_parser("new", help="write a commented scene file for a task", description=__doc__)
    new.add_argument("--task", required=True, choices=list(APPLICATIONS), help="the scene's task")
    new.add_argument("--out", required=True, help="the scene file to write (.toml; never replaces a file)")
    new.set_defaults(func=run_new)
    keys = actions.add_parser("keys", help="print every scene key (Markdown table)", description=__doc__)
    keys.set_defaults(func=run_keys)


def run_new(args) -> int:
    from pathlib import Path

    from doefab.errors import DoefabError
    from doefab.io import atomic_write_text
    from doefab.pipeline.scenekeys import template

    out = Path(args.out)
    if out.suffix != ".toml":
        raise DoefabError(f"--out {out}: a scene file ends in .toml (e.g. my_camera.toml)")
    if out.exists():
        raise DoefabError(f"--out {out} exists: doefab never replaces a file of yours; choose another name")
    if not out.parent.is_dir():
        raise DoefabError(f"--out {out}: its folder {out.parent} does not exist; create it first")
    atomic_write_text(out, template(args.task))
    print(f"wrote {out}: edit the camera, optics, design and fabrication keys, then `doefab doctor {out}` "
          f"explains the system and `doefab run {out}` runs it")
    return 0


def run_keys(args) -> int:
    from doefab.pipeline.scenekeys import key_table_markdown

    print(key_table_markdown())
    return 0

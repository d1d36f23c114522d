"""Sphinx extension of the doefab site: pages that come from the repository itself, so nothing is written twice.

- The API reference lists ``doefab.__all__`` and ``holder_cad.__all__`` (written to ``api/reference.rst`` when
  the build starts); every public name without a docstring, and every public callable that takes a length
  without stating its unit, is a warning (an error under ``-W``).
- Directives: ``scene-keys`` (every scene key, from ``doefab.pipeline.scenekeys.key_table_markdown()``, the
  table that also validates scenes and writes ``doefab scene new``'s template), ``docstring`` (a module's
  docstring), ``doefab-help`` (a subcommand's ``--help``), ``doefab-command`` (runs commands and shows what
  they printed), ``holder-params`` (the holder's parameters, defaults and ranges), ``substrates`` (the built-in
  substrates with their sources), ``budget-keys`` (every tolerance budget key by source of error).
- Results pages (``doefab_results``) and the mask-set page (``doefab_fab``) have their own modules.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import io
import os
import re
import shlex
import shutil
import tempfile
import time
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

import doefab_fab
import doefab_results

log = logging.getLogger("doefab_docs")
ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"

# --- the public API and its docstrings -------------------------------------------------------------------

# parameter names that carry a length (or a list of lengths): their docstring must state the unit
LENGTH_WORDS = ("distance", "pitch", "diameter", "wavelength", "depth", "height", "gap", "aperture", "radius",
                "overlay", "bias", "roughness", "rounding", "corr", "center", "die")
LENGTH_SUFFIXES = ("_m", "_mm", "_um", "_nm")
UNIT_PATTERN = re.compile(r"metre|meter|\bm\b|\bmm\b|\bnm\b|µm|\bum\b|millimetre|SI units")


def public_names() -> list[tuple[str, str, object]]:
    """(module, name, object) of every public name: ``doefab.__all__`` (less ``__version__``) and
    ``holder_cad.__all__``."""
    out = []
    for modname in ("doefab", "holder_cad"):
        mod = importlib.import_module(modname)
        for name in mod.__all__:
            if name.startswith("__"):
                continue
            out.append((modname, name, getattr(mod, name)))
    return out


def _attribute_doc(obj_module: str, name: str) -> str:
    """The ``#:`` comment documenting a module-level constant (autodoc's source for data)."""
    from sphinx.pycode import ModuleAnalyzer

    try:
        docs = ModuleAnalyzer.for_module(obj_module).find_attr_docs()
    except Exception:  # noqa: BLE001 - no source: no attribute doc
        return ""
    return "\n".join(docs.get(("", name), []))


def _home_module(modname: str, name: str) -> str:
    """Where a re-exported constant is defined (doefab's lazy export table, or the package itself)."""
    mod = importlib.import_module(modname)
    return getattr(mod, "_EXPORTS", {}).get(name, modname)


def _takes_lengths(obj) -> list[str]:
    try:
        params = inspect.signature(obj).parameters
    except (TypeError, ValueError):
        return []
    return [p for p in params if p not in ("self", "cls") and (any(w in p.lower() for w in LENGTH_WORDS)
                                                              or p.lower().endswith(LENGTH_SUFFIXES))]


def docstring_problems() -> list[str]:
    """Every public name (and public method or property of a public class) without a docstring, and every
    public callable whose parameters include a length but whose docstring names no unit."""
    problems = []
    for modname, name, obj in public_names():
        full = f"{modname}.{name}"
        if inspect.isclass(obj) or inspect.isroutine(obj):
            doc = inspect.getdoc(obj) or ""
            if not doc.strip():
                problems.append(f"{full} has no docstring")
                continue
            lengths = _takes_lengths(obj)
            if lengths and not UNIT_PATTERN.search(doc):
                problems.append(f"{full} takes lengths ({', '.join(lengths)}) but its docstring states no unit")
            if inspect.isclass(obj):
                for member, value in vars(obj).items():
                    if member.startswith("_"):
                        continue
                    target = value.fget if isinstance(value, property) else getattr(value, "__func__", value)
                    if not (inspect.isfunction(target) or isinstance(value, property)):
                        continue
                    if not (inspect.getdoc(target) or "").strip():
                        problems.append(f"{full}.{member} has no docstring")
        elif not _attribute_doc(_home_module(modname, name), name).strip():
            problems.append(f"{full} (a constant) has no '#:' comment documenting it")
    return problems


API_HEADER = """\
..
   Generated by docs/_ext/doefab_docs.py from doefab.__all__ and holder_cad.__all__: do not edit.

Reference
=========

"""


def write_api_reference() -> None:
    """``api/reference.rst``: one autosummary table per package, one generated page per public name."""
    groups: dict[str, list[str]] = {"doefab": [], "holder_cad": []}
    for modname, name, _ in public_names():
        groups[modname].append(name)
    text = [API_HEADER]
    titles = {"doefab": "doefab (SI units: metres)", "holder_cad": "holder_cad (millimetres)"}
    for modname, names in groups.items():
        text += [titles[modname], "-" * len(titles[modname]), "", f".. currentmodule:: {modname}", "",
                 ".. autosummary::", "   :toctree: generated", "   :nosignatures:", ""]
        text += [f"   {n}" for n in sorted(names, key=str.lower)]
        text.append("")
    _write_if_changed(DOCS / "api" / "reference.rst", "\n".join(text))


def _write_if_changed(path: Path, text: str) -> None:
    """Write ``text`` unless the file holds it already (an unchanged file is not rebuilt)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


# --- directives ----------------------------------------------------------------------------------------

def _module_doc(modname: str) -> str:
    return inspect.getdoc(importlib.import_module(modname)) or ""


class MarkdownDirective(SphinxDirective):
    """A directive whose output is Markdown, parsed in place (MyST parses nested content as Markdown)."""

    def parse_markdown(self, lines: list[str]) -> list[nodes.Node]:
        container = nodes.container()
        self.state.nested_parse(StringList(lines, source=self.get_source_info()[0]), self.content_offset, container)
        return container.children


class SceneKeys(MarkdownDirective):
    """Every scene key with its unit, range, default and meaning: ``doefab.pipeline.scenekeys``' own table."""

    def run(self):
        from doefab.pipeline import scenekeys

        self.env.note_dependency(inspect.getsourcefile(scenekeys))
        return self.parse_markdown(scenekeys.key_table_markdown().splitlines())


class Docstring(MarkdownDirective):
    """A module's docstring, from its second paragraph on (``:all:`` for the whole of it)."""

    required_arguments = 1
    option_spec = {"all": directives.flag}

    def run(self):
        doc = _module_doc(self.arguments[0])
        paragraphs = doc.split("\n\n")
        text = doc if "all" in self.options else "\n\n".join(paragraphs[1:])
        self.env.note_dependency(inspect.getsourcefile(importlib.import_module(self.arguments[0])))
        return self.parse_markdown(text.splitlines())


def _parser_help(sub: str | None) -> str:
    from doefab.cli import build_parser

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"
    try:
        parser = build_parser()
        for name in (sub or "").split():  # "scene new": a subcommand's own subcommand
            action = next(a for a in parser._actions if getattr(a, "choices", None) and name in a.choices)
            parser = action.choices[name]
        return parser.format_help()
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old


class DoefabHelp(SphinxDirective):
    """``doefab [SUBCOMMAND [ACTION]] --help``, as the installed parser prints it."""

    optional_arguments = 1
    final_argument_whitespace = True

    def run(self):
        sub = self.arguments[0] if self.arguments else None
        try:
            text = _parser_help(sub)
        except StopIteration:
            raise self.error(f"doefab has no subcommand {sub!r}") from None
        text = f"$ doefab {sub + ' ' if sub else ''}--help\n{text}"
        block = nodes.literal_block(text, text)
        block["language"] = "text"
        block["classes"].append("doefab-command")
        return [block]


class DoefabCommand(SphinxDirective):
    """Run ``doefab`` commands during the build and show each with what it printed and its exit status.

    The commands (one, or several joined by `` && ``) run one after another in one fresh folder that links the
    repository's ``masks/`` and ``scenes/``, so a later command reads what an earlier one wrote; ``:tail: N``
    keeps the last N lines of each long output, ``:status: N`` is the exit status the last command must end with
    (default 0; every earlier one must end with 0), ``:files:`` lists what they wrote, ``:write: NAME`` first
    writes the directive's content to the file NAME (shown above the commands).
    """

    required_arguments = 1
    final_argument_whitespace = True
    has_content = True
    option_spec = {"tail": directives.nonnegative_int, "status": int, "files": directives.flag,
                   "write": directives.unchanged_required}

    def run(self):
        commands = [c.strip() for c in self.arguments[0].split(" && ")]
        argvs = [shlex.split(c) for c in commands]
        if any(not argv or argv[0] != "doefab" for argv in argvs):
            raise self.error("doefab-command runs doefab commands only")
        want = self.options.get("status", 0)
        work = Path(tempfile.mkdtemp(prefix="doefab-docs-"))
        for name in ("masks", "scenes"):
            (work / name).symlink_to(ROOT / name, target_is_directory=True)
        if "write" in self.options:  # the directive's content is a file the command reads
            (work / self.options["write"]).write_text("\n".join(self.content) + "\n")
        shown = [f"$ cat {self.options['write']}", *self.content] if "write" in self.options else []
        cwd = os.getcwd()
        t0 = time.perf_counter()
        try:
            os.chdir(work)
            for i, (command, argv) in enumerate(zip(commands, argvs)):
                status, lines = self._run_one(argv)
                expected = want if i == len(commands) - 1 else 0
                if status != expected:
                    raise self.error(f"{command} exited with status {status} (expected {expected}):\n"
                                     + "\n".join(lines))
                tail = self.options.get("tail")
                if tail is not None and len(lines) > tail:
                    lines = [f"[… {len(lines) - tail} lines before these …]"] + lines[-tail:]
                shown += [f"$ {command}", *lines, f"[exit status {status}]"]
            files = sorted(str(p.relative_to(work)) for p in work.rglob("*")
                           if p.is_file() and not str(p.relative_to(work)).startswith(("masks", "scenes")))
        finally:
            os.chdir(cwd)
            shutil.rmtree(work, ignore_errors=True)
        seconds = time.perf_counter() - t0
        text = "\n".join(shown)
        if "files" in self.options:
            given = self.options.get("write")
            text += "\n\nwritten:\n" + "\n".join(f"  {f}" for f in files if ".doefab-output" not in f and f != given)
        block = nodes.literal_block(text, text)
        block["language"] = "text"
        block["classes"].append("doefab-command")  # long lines wrap (_static/doefab.css)
        caption = nodes.paragraph(text=f"Run while this page was built ({seconds:.1f} s).")
        caption["classes"].append("doefab-command-caption")
        return [block, caption]

    @staticmethod
    def _run_one(argv: list[str]) -> tuple[int, list[str]]:
        """Exit status and printed lines (stdout and stderr) of ``doefab ARGV`` run in this process."""
        from doefab.cli import main

        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            try:
                status = main(argv[1:])
            except SystemExit as exc:  # argparse's own exits
                status = exc.code
        return status, out.getvalue().rstrip("\n").splitlines()


class SubstratesTable(MarkdownDirective):
    """The built-in substrates (``doefab.optics.materials.SUBSTRATES``): name, published source, fitted range, and
    the index, 2π height and 16-level step they give at 550 nm."""

    def run(self):
        from doefab.optics import materials

        lam = 550e-9
        rows = ["| `material` | source of the dispersion | fitted range (µm) | n at 550 nm | 2π height at 550 nm (nm) "
                "| level step, 16 levels (nm) |", "| --- | --- | --- | --- | --- | --- |"]
        for name, sub in materials.SUBSTRATES.items():
            n = float(sub.material.index(lam))
            h2pi = lam / (n - 1) * 1e9
            rows.append(f"| `{name}` | {sub.source} | {sub.range_um[0]:g}–{sub.range_um[1]:g} | {n:.4f} | "
                        f"{h2pi:.1f} | {h2pi / 16:.2f} |")
        self.env.note_dependency(inspect.getsourcefile(materials))
        return self.parse_markdown(rows)


class BudgetKeysTable(MarkdownDirective):
    """Every budget key, by source of error (``doefab.tolerance.sources.SOURCES``, the table that validates budget
    files and draws the parts): its range, the shipped budget's value, and the kinds the report judges it as."""

    def run(self):
        import tomllib

        from doefab.tolerance import kinds, sources
        from doefab.tolerance.errors import DEFAULT_BUDGET

        shipped = tomllib.loads(DEFAULT_BUDGET.read_text())
        rows = ["| source of error | budget key | range | shipped value | judged as |",
                "| --- | --- | --- | --- | --- |"]
        for src in sources.SOURCES:
            judged = ", ".join(k.name for k in kinds.KINDS if k.source == src.name) or "—"
            for k in src.keys:
                rng = "true or false" if k.lo is None else f"{k.lo:g}–{k.hi:g}" + (" (whole)" if k.whole else "")
                value = shipped.get(k.section, {}).get(k.key, "—")
                shown = str(value).lower() if isinstance(value, bool) else value
                rows.append(f"| {src.name} | `{k.section}.{k.key}` | {rng} | {shown} | {judged} |")
        for mod in (sources, kinds):
            self.env.note_dependency(inspect.getsourcefile(mod))
        self.env.note_dependency(str(DEFAULT_BUDGET))
        return self.parse_markdown(rows)


class HolderParamsTable(MarkdownDirective):
    """Every holder parameter: its default, its allowed range (millimetres) and why."""

    def run(self):
        import dataclasses

        from holder_cad.params import PARAM_RANGES, HolderParams

        p = HolderParams()
        rows = ["| parameter | default | allowed range | note |", "| --- | --- | --- | --- |"]
        for f in dataclasses.fields(HolderParams):
            value = getattr(p, f.name)
            lo_hi = PARAM_RANGES.get(f.name)
            rng = f"{lo_hi[0]:g} – {lo_hi[1]:g}" if lo_hi else "—"
            note = lo_hi[2] if lo_hi else ""
            rows.append(f"| `{f.name}` | {value:g} | {rng} | {note} |" if isinstance(value, (int, float))
                        else f"| `{f.name}` | `{value}` | {rng} | {note} |")
        self.env.note_dependency(inspect.getsourcefile(HolderParams))
        return self.parse_markdown(rows)


# --- events ------------------------------------------------------------------------------------------------

def _on_config_inited(app, config) -> None:
    write_api_reference()
    for problem in doefab_results.write_pages():
        log.warning(problem, type="doefab", subtype="results")
    for problem in doefab_fab.write_figures():
        log.warning(problem, type="doefab", subtype="fab")


def _constant_doc(app, what, name, obj, options, lines) -> None:
    """A public constant's docstring is the ``#:`` comment where it is defined (not its type's docstring)."""
    if what != "data" or not name.startswith(("doefab.", "holder_cad.")):
        return
    modname, _, attr = name.rpartition(".")
    doc = _attribute_doc(_home_module(modname, attr), attr)
    if doc:
        lines[:] = doc.splitlines() + [""]


def _on_builder_inited(app) -> None:
    for problem in docstring_problems():
        log.warning(f"public API: {problem}", type="doefab", subtype="docstring")


def setup(app):
    app.connect("config-inited", _on_config_inited)
    app.connect("builder-inited", _on_builder_inited, priority=400)
    app.connect("autodoc-process-docstring", _constant_doc)
    app.add_directive("scene-keys", SceneKeys)
    app.add_directive("docstring", Docstring)
    app.add_directive("doefab-help", DoefabHelp)
    app.add_directive("doefab-command", DoefabCommand)
    app.add_directive("holder-params", HolderParamsTable)
    app.add_directive("substrates", SubstratesTable)
    app.add_directive("budget-keys", BudgetKeysTable)
    doefab_fab.setup(app)
    return {"version": "1", "parallel_read_safe": False, "parallel_write_safe": True}

"""The documentation site, checked like code: built strictly (every warning an error, every tutorial executed),
then every page opened in headless Chromium (Debian's chromium, driven over its DevTools pipe): every page loads
without a script error, every image loads, no internal link is broken. Also: the generators' own checks fail
when they should, and the README's commands are the docs' commands."""

import json
import os
import re
import select
import shutil
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import unquote, urlparse

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "docs" / "_ext"))

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


# --- the generators' checks ------------------------------------------------------------------------------

def test_every_public_name_has_a_docstring_with_units():
    import doefab_docs

    assert doefab_docs.docstring_problems() == []


def test_a_public_name_without_docstring_or_unit_is_reported(monkeypatch):
    import doefab_docs

    def undocumented(wavelength):
        return wavelength

    def unitless(pitch):
        """Does something with a pitch."""
        return pitch

    monkeypatch.setattr(doefab_docs, "public_names", lambda: [("doefab", "undocumented", undocumented),
                                                              ("doefab", "unitless", unitless)])
    problems = doefab_docs.docstring_problems()
    assert problems == ["doefab.undocumented has no docstring",
                        "doefab.unitless takes lengths (pitch) but its docstring states no unit"]


def test_results_pages_show_every_results_file_and_report_one_that_is_not(tmp_path, monkeypatch):
    import doefab_results

    monkeypatch.setattr(doefab_results, "OUT", tmp_path / "generated")
    assert doefab_results.write_pages() == []
    table = (tmp_path / "generated" / "psf_error_vs_time.md").read_text()
    assert ".venv/bin/python benchmarks/psf_error_vs_time.py" in table  # the command, from the docstring
    assert "| spectral (default) |" in table  # the table itself, as the script wrote it
    results = tmp_path / "results"
    shutil.copytree(REPO / "benchmarks" / "results", results)
    (results / "new_benchmark.md").write_text("| a |\n| --- |\n| 1 |\n")
    monkeypatch.setattr(doefab_results, "RESULTS", results)
    problems = doefab_results.write_pages()
    assert len(problems) == 1 and "new_benchmark.md is on no results page" in problems[0]


def test_a_results_table_that_prints_nan_is_reported(tmp_path):
    import doefab_results

    page = tmp_path / "depth_error_sources.md"
    committed = ("Binned errors.\n\n| bin | val: δ<1.25 | test: δ<1.25 |\n| --- | --- | --- |\n"
                 "| 0–0.01 | — | — |\n| ≥ 0.1 | 0.898 | 0.843 |\n")  # a bin without pixels prints '—'
    cases = {"| NaN | — |": 1, "| nan | — |": 1, "| +nan ± 0.4 dB | — |": 1, "| nan dB / 0.5 | — |": 1,
             "| 0.5 | nanometre |": 0}  # a word that begins with "nan" is no number
    for cell, found in cases.items():
        page.write_text(committed.replace("| — | — |", cell, 1))
        problems = []
        doefab_results.markdown_body(page, problems)
        assert len(problems) == found and all("depth_error_sources.md prints 'nan'" in p for p in problems), cell
    page.write_text(committed + "\nA paragraph that says nan | once.\n")  # prose is not a table
    problems = []
    doefab_results.markdown_body(page, problems)
    assert problems == []


def test_the_fab_page_explains_every_manifest_field():
    from doefab_fab import exporter_field_names, manifest_field_names

    page = (REPO / "docs" / "fab" / "mask-set.md").read_text()
    table = page.split("```{manifest-fields}")[1].split("```")[0]
    explained = {name for line in table.splitlines() if line.startswith("| `")
                 for name in re.findall(r"`([^`]+)`", line.split("|")[1])}
    newer = set(re.search(r"^:newer:(.*)$", table, re.M).group(1).split())  # written by the exporter since
    manifest = json.loads((REPO / "masks" / "grating" / "manifest.json").read_text())
    assert explained == manifest_field_names(manifest) | newer
    assert newer <= exporter_field_names() and not newer & manifest_field_names(manifest)


# --- the strict build ------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site built as ``bash scripts/docs.sh`` builds it (warnings are errors), into a fresh folder."""
    out = tmp_path_factory.mktemp("site")
    (out / "tmp").mkdir()  # the tutorials' working folders (tempfile.mkdtemp) stay inside the test's folder
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                           "-d", str(out / "doctrees"), str(REPO / "docs"), str(out / "html")],
                          capture_output=True, text=True, timeout=1800, cwd=REPO,
                          env={**os.environ, "DOEFAB_DOCS_REUSE_TUTORIALS": "0", "TMPDIR": str(out / "tmp")})
    assert proc.returncode == 0, (f"the documentation does not build strictly (install the docs extra with "
                                  f"bash scripts/setup.sh):\n{proc.stdout[-4000:]}\n{proc.stderr[-6000:]}")
    return out / "html", time.perf_counter() - t0


def test_the_site_builds_strictly_with_every_tutorial_run(site):
    html, seconds = site
    tutorials = sorted((REPO / "docs" / "examples").glob("plot_*.py"))
    assert len(tutorials) >= 6
    for script in tutorials:
        page = (html / "tutorials" / f"{script.stem}.html").read_text()
        assert "sphx-glr-script-out" in page or "sphx-glr-single-img" in page, f"{script.name} shows no output"
        assert "Total running time of the script" in page
    for name in ("doefab.Camera", "doefab.split_aperture_psf", "holder_cad.write_holder"):
        assert (html / "api" / "generated" / f"{name}.html").is_file()
    # each tutorial that writes files wrote them in a fresh temporary folder, none in the repository or beside it
    written = {p.name.rsplit("-", 1)[0] for p in (html.parent / "tmp").iterdir() if p.is_dir()}
    made = {m for s in tutorials for m in re.findall(r'mkdtemp\(prefix="([\w-]+)-"\)', s.read_text())}
    assert len(made) >= 5 and made <= written, (made, written)


def test_the_readme_commands_are_the_docs_commands(site):
    html, _ = site
    readme = (REPO / "README.md").read_text()
    block = readme.split("<!-- commands-start -->")[1].split("<!-- commands-end -->")[0]
    commands = [line.split("#")[0].strip() for line in block.splitlines() if line.startswith("bash ")]
    assert commands, "README.md has no commands between its <!-- commands-start/end --> markers"
    front = re.sub(r"<[^>]+>", "", (html / "index.html").read_text())
    for command in commands:
        assert command in front, command


# --- every page in Chromium ------------------------------------------------------------------------------

class DevTools:
    """Chromium driven over ``--remote-debugging-pipe``: JSON messages, each ended by a NUL byte, on fds 3/4."""

    def __init__(self, exe: str, profile: Path):
        import fcntl

        to_child, self._w = os.pipe()
        self._r, from_child = os.pipe()

        def wire():  # in the child: its fd 3 reads our commands, its fd 4 writes its answers
            a = fcntl.fcntl(to_child, fcntl.F_DUPFD_CLOEXEC, 10)
            b = fcntl.fcntl(from_child, fcntl.F_DUPFD_CLOEXEC, 10)
            os.dup2(a, 3)  # dup2 makes 3 and 4 inheritable; close_fds=False keeps them for the exec
            os.dup2(b, 4)

        self.proc = subprocess.Popen([exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                      "--remote-debugging-pipe", "about:blank"], preexec_fn=wire, close_fds=False,
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        os.close(to_child)
        os.close(from_child)
        self._buf, self._id, self.events = b"", 0, []
        target = self.call("Target.createTarget", url="about:blank")["targetId"]
        self.session = self.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        for domain in ("Page", "Runtime", "Network"):
            self.call(f"{domain}.enable", session=True)

    def _read(self, timeout: float) -> dict:
        end = time.monotonic() + timeout
        while b"\0" not in self._buf:
            left = end - time.monotonic()
            if left <= 0 or not select.select([self._r], [], [], left)[0]:
                raise TimeoutError("Chromium did not answer")
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed its DevTools pipe")
            self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def call(self, method: str, session: bool = False, timeout: float = 60, **params) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = self.session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        while True:
            got = self._read(timeout)
            if got.get("id") == self._id:
                if "error" in got:
                    raise RuntimeError(f"{method}: {got['error']}")
                return got.get("result", {})
            self.events.append(got)

    def wait_event(self, method: str, timeout: float = 60) -> dict:
        for i, e in enumerate(self.events):
            if e.get("method") == method:
                return self.events.pop(i)
        while True:
            got = self._read(timeout)
            if got.get("method") == method:
                return got
            self.events.append(got)

    def close(self):
        try:
            self.call("Browser.close", timeout=10)
        except (RuntimeError, TimeoutError, OSError):
            pass
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        os.close(self._w)
        os.close(self._r)


# what each page reports once loaded: lazy images are made eager, then every image is waited for
PAGE_REPORT = """(async () => {
  const imgs = Array.from(document.images);
  imgs.forEach(i => { if (i.loading === 'lazy') i.loading = 'eager'; });
  await Promise.all(imgs.map(i => i.complete ? null : new Promise(r => { i.onload = i.onerror = r;
                                                                           setTimeout(r, 20000); })));
  return {title: document.title,
          article: (document.querySelector('article') || document.body).innerText.trim().length,
          images: imgs.map(i => ({src: i.currentSrc || i.src, width: i.naturalWidth})),
          links: Array.from(document.querySelectorAll('a[href]')).map(a => a.href),
          ids: Array.from(document.querySelectorAll('[id]')).map(e => e.id),
          sheets: document.styleSheets.length};
})()"""


def test_every_page_in_chromium(site):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        if os.environ.get("DOEFAB_SKIP_BROWSER") == "1":
            pytest.skip("DOEFAB_SKIP_BROWSER=1: the browser checks were skipped on request")
        pytest.fail("Debian's chromium is not installed: scripts/setup.sh installs it (as root); the browser checks "
                    "are part of the suite (set DOEFAB_SKIP_BROWSER=1 to skip them on a machine without it)")
    html, _ = site
    pages = sorted(p for p in html.rglob("*.html") if not p.relative_to(html).parts[0].startswith("_"))
    assert len(pages) > 40
    browser = DevTools(chromium, html.parent / "chromium-profile")
    reports, problems = {}, []
    try:
        for page in pages:
            name = page.relative_to(html).as_posix()
            browser.events.clear()
            browser.call("Page.navigate", session=True, url=page.as_uri())
            browser.wait_event("Page.loadEventFired")
            got = browser.call("Runtime.evaluate", session=True, expression=PAGE_REPORT, awaitPromise=True,
                               returnByValue=True)
            if "exceptionDetails" in got:
                problems.append(f"{name}: the page report failed: {got['exceptionDetails']}")
                continue
            report = reports[page] = got["result"]["value"]
            if not report["title"] or report["article"] < 50 or report["sheets"] < 2:
                problems.append(f"{name}: no title, no text or no style sheets")
            problems += [f"{name}: image does not load: {i['src']}" for i in report["images"] if i["width"] <= 0]
            for e in browser.events:
                if e.get("method") == "Runtime.exceptionThrown":
                    problems.append(f"{name}: script error: {e['params']['exceptionDetails'].get('text')}")
                if e.get("method") == "Network.loadingFailed" and not e["params"].get("canceled"):
                    problems.append(f"{name}: a resource failed to load: {e['params'].get('errorText')}")
    finally:
        browser.close()
    ids = {page: set(r["ids"]) for page, r in reports.items()}
    n_links = 0
    for page, report in reports.items():
        for href in report["links"]:
            url = urlparse(href)
            if url.scheme != "file":
                continue
            n_links += 1
            target = Path(unquote(url.path))
            where = f"{page.relative_to(html).as_posix()} → {href}"
            if not target.exists():
                problems.append(f"{where}: no such file")
            elif url.fragment and target.suffix == ".html":
                known = ids.get(target) or set(re.findall(r'id="([^"]+)"', target.read_text()))
                if unquote(url.fragment) not in known:
                    problems.append(f"{where}: no such anchor")
    assert not problems, "\n".join(problems[:40])
    assert n_links > 500
    images = {page.relative_to(html).as_posix(): len(r["images"]) for page, r in reports.items()}
    for name in [f"tutorials/{s.stem}.html" for s in (REPO / "docs" / "examples").glob("plot_*.py")]:
        assert images[name] >= 1, name
    assert images["fab/mask-set.html"] >= 2 and images["results/psf.html"] >= 1


def _doefab_commands(text: str) -> list[str]:
    """Every ``doefab …`` command written in backticks or at the start of a code-block line."""
    found = re.findall(r"`(doefab [^`]+)`", text)
    blocks = "\n".join(re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S))
    found += [m.split("  #")[0].strip() for m in re.findall(r"(?m)^(doefab [^\n]+)$", blocks)]
    # a bare "doefab run" in prose names a command, it is not one to run
    # placeholders (``--task T``, ``FILE.toml``) stand for a value, they are not one
    placeholder = re.compile(r"(^|[\s=/])[A-Z][A-Z_]*(\.[a-z]+)?($|\s)")
    return [c for c in found if "…" not in c and "..." not in c and len(c.split()) > 2 and not placeholder.search(c)]


@pytest.mark.parametrize("page", ["README.md", "docs/guide/commands.md"])
def test_every_command_the_readme_and_the_guide_write_parses(page):
    """The README's command table and the guide's examples are commands the CLI accepts as written (flags that
    exist, values of the right kind): a renamed flag breaks this test, not a user's first try."""
    import shlex

    from doefab.cli import build_parser

    cmds = _doefab_commands((REPO / page).read_text())
    assert len(cmds) >= 5, cmds
    parser = build_parser()
    for c in cmds:
        argv = [a for a in shlex.split(c)[1:]]
        try:
            parser.parse_args(argv)
        except SystemExit as exc:  # --help exits 0
            if exc.code != 0:
                raise AssertionError(f"{page}: `{c}` does not parse (exit {exc.code})") from None


def test_the_readme_is_a_front_page():
    """The README stays a front page: at most 200 lines, opening with the two commands."""
    lines = (REPO / "README.md").read_text().splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines"
    assert lines[0].startswith("# ") and lines[2] == "<!-- commands-start -->"


def test_the_citing_page_and_citation_cff_cite_the_same_paper_and_version():
    """CITATION.cff parses, names the package's version, and its paper (title, DOI, every author, year) is the
    one the Citing page's BibTeX gives."""
    import yaml

    import doefab

    root = Path(__file__).resolve().parents[2]
    cff = yaml.safe_load((root / "CITATION.cff").read_text())
    page = (root / "docs" / "citing.md").read_text()
    assert cff["cff-version"] == "1.2.0" and cff["version"] == doefab.__version__
    assert f"version = {{{doefab.__version__}}}" in page
    paper = cff["references"][0]
    assert paper["title"] in page and f"doi     = {{{paper['doi']}}}" in page and f"year    = {{{paper['year']}}}" in page
    bib = page.split("author  = {", 1)[1].split("},\n", 1)[0]
    names = " ".join(bib.split()).split(" and ")
    ascii_family = {"Côté": "C{\\^o}t{\\'e}"}
    assert names == [f"{ascii_family.get(a['family-names'], a['family-names'])}, {a['given-names']}"
                     for a in paper["authors"]]


def test_a_results_title_is_shown_once_per_page(tmp_path, monkeypatch):
    """A results file's title that repeats its page's section heading, or the title of a variant included before
    it, is left out of the generated file; the headings inside a file stay."""
    import doefab_results

    monkeypatch.setattr(doefab_results, "OUT", tmp_path / "generated")
    assert doefab_results.write_pages() == []
    gen = {p.stem: p.read_text() for p in (tmp_path / "generated").glob("*.md")}
    coverage = "Diagnosis coverage on parts of known errors"
    variants = [n for n in gen if n.startswith("diagnose_coverage")]
    assert len(variants) >= 3 and sum(f"### {coverage}" in gen[n] for n in variants) <= 1
    title = "Where a network-judged part's time goes"
    assert f"## {title}" in (REPO / "docs" / "results" / "tolerance.md").read_text().replace("### ", "## ")
    assert title not in gen["judge_profile"]
    for design in ("streak", "grating"):  # each tolerance report keeps its own sections
        assert "#### Monte Carlo" in gen[f"tolerance_{design}"] and "#### Simulation grid" in gen[f"tolerance_{design}"]
    made = doefab_results.drop_repeated_headings({"a": "### Shared\n\ntext"})
    assert made == {"a": "### Shared\n\ntext"}  # a file no page includes keeps its title

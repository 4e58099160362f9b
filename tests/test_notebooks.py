"""The course: notebooks committed clean and complete, every lesson run top to bottom, the figures its
prose quotes checked against what it printed, and the course site built with strict checks and
every link and image on it resolved.

A lesson runs once per test session at most, through the site's own cache (docs/hooks/course.py):
``test_a_lesson_runs_and_says_what_it_printed`` executes it (or finds the execution of the same code
on the same package sources in .cache/course/), and the site built afterwards shows those outputs
without executing anything. tests/conftest.py orders the session so that the site's tests run last,
after every lesson test; a site built before its lessons (``-k site``) executes them itself.

Quoting a figure: a lesson's prose that quotes a figure its code prints marks it with an HTML comment
right after it that names the output line it comes from, ``16667<!--output steps_to_90-->``
(invisible in Jupyter and on the site). A code cell next to that prose (between the previous and the
next markdown cell) must print, on one line, the label and after it the figure as written. Prose
that describes a figure without quoting it should not hard-code it.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urljoin, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def _course_module():
    spec = importlib.util.spec_from_file_location("course_hook", ROOT / "docs" / "hooks" / "course.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


course = _course_module()


def test_there_is_a_lesson_per_topic():
    assert [n.stem[:2] for n in NOTEBOOKS] == [f"{i:02d}" for i in range(len(NOTEBOOKS))] and len(NOTEBOOKS) >= 9


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_a_notebook_is_committed_without_outputs_and_with_goals_and_exercises(notebook):
    cells = json.loads(notebook.read_text())["cells"]
    code = [c for c in cells if c["cell_type"] == "code"]
    assert all(c["outputs"] == [] and c["execution_count"] is None for c in code), "strip the outputs before committing"
    first = "".join(cells[0]["source"])
    assert first.startswith("# ") and "**You will:**" in first
    markdown = "".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
    assert "## Exercises" in markdown
    assert any("solution" in c.get("metadata", {}).get("tags", []) for c in code), "exercises need a solution cell"
    # The course uses the public API only: no private names imported.
    assert not any(" import _" in line for c in code for line in "".join(c["source"]).splitlines())


def test_every_lesson_is_on_the_site_and_its_index():
    site, index = (ROOT / "mkdocs.yml").read_text(), (ROOT / "docs" / "index.md").read_text()
    for notebook in NOTEBOOKS:
        assert f"course/{notebook.name}" in site and f"course/{notebook.name}" in index, notebook.name


# --------------------------------------------------------------------------------------------------
# The cache of executed lessons (docs/hooks/course.py)


def test_a_lesson_is_executed_again_when_its_code_or_the_package_changes_not_its_prose(tmp_path, monkeypatch):
    import nbformat

    package = tmp_path / "common"
    package.mkdir()
    (package / "module.py").write_text("x = 1\n")
    monkeypatch.setattr(course, "ROOT", tmp_path)
    monkeypatch.setattr(course, "INPUTS", ("common", "pyproject.toml"))
    notebook = tmp_path / "lesson.ipynb"
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# prose"), nbformat.v4.new_code_cell("print(1)")])
    nbformat.write(nb, notebook)
    key = course.cache_key(notebook)
    nb.cells[0].source = "# other prose"
    nbformat.write(nb, notebook)
    assert course.cache_key(notebook) == key
    nb.cells[1].source = "print(2)"
    nbformat.write(nb, notebook)
    assert course.cache_key(notebook) != key
    key = course.cache_key(notebook)
    (package / "module.py").write_text("x = 2\n")
    assert course.cache_key(notebook) != key
    key = course.cache_key(notebook)
    (package / "__pycache__").mkdir()
    (package / "__pycache__" / "module.cpython-311.pyc").write_bytes(b"built")
    (tmp_path / "pyproject.toml").write_text("[project]\n")
    assert course.cache_key(notebook) != key  # pyproject.toml appeared; the bytecode does not count
    key = course.cache_key(notebook)
    (package / "__pycache__" / "module.cpython-311.pyc").write_bytes(b"built again")
    assert course.cache_key(notebook) == key


def test_the_files_an_executed_lesson_writes_leave_with_its_kernel(tmp_path):
    """Lessons write their GIFs into tempfile's folders: executed for the site or a test run, they
    must not pile up in /tmp (a student's own Jupyter keeps them)."""
    import nbformat

    notebook = tmp_path / "lesson.ipynb"
    nbformat.write(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(
        "import tempfile\nfolder = tempfile.mkdtemp(prefix='course-test-')\nprint(folder)")]), notebook)
    folder = course.execute(notebook).cells[0].outputs[0]["text"].strip()
    assert folder and not os.path.exists(folder)


def test_the_cache_key_is_the_same_for_mkdocs_and_for_pytest(tmp_path):
    """`mkdocs serve` (the console script), `python -m mkdocs` (the site test) and pytest (the lesson
    tests) see different sys.path entries (the working directory, and in it a stray *.egg-info); a
    lesson they all run must get the same key. Checked on a copy of the hook in a made-up project."""
    import shutil

    root = tmp_path / "project"
    (root / "docs" / "hooks").mkdir(parents=True)
    shutil.copy(ROOT / "docs" / "hooks" / "course.py", root / "docs" / "hooks")
    (root / "notebooks").mkdir()
    shutil.copy(NOTEBOOKS[0], root / "notebooks")
    (root / "common").mkdir()
    (root / "common" / "module.py").write_text("x = 1\n")
    for name, version in (("nav-curriculum", "0.1.0"), ("stray-package", "9.9")):  # as `pip install -e` leaves
        egg = root / f"{name.replace('-', '_')}.egg-info"
        egg.mkdir()
        (egg / "PKG-INFO").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    script = ("import sys; sys.path.insert(0, sys.argv[1]); import course; "
              "print(course.cache_key(course.NOTEBOOKS / sys.argv[2]))")
    keys = {subprocess.run([sys.executable, *flag, "-c", script, str(root / "docs" / "hooks"), NOTEBOOKS[0].name],
                           cwd=cwd, capture_output=True, text=True, check=True).stdout
            for cwd, flag in ((root, []), (tmp_path, []), (tmp_path, ["-I"]))}
    assert len(keys) == 1, keys


@pytest.mark.slow
def test_a_lesson_runs_once_and_a_failed_run_is_not_cached(tmp_path, monkeypatch):
    import nbformat
    from nbclient.exceptions import CellExecutionError

    monkeypatch.setattr(course, "CACHE", tmp_path / "cache")
    notebook = tmp_path / "lesson.ipynb"
    cells = [nbformat.v4.new_code_cell("import os; print(os.getcwd())"), nbformat.v4.new_code_cell("1 / 0")]
    nbformat.write(nbformat.v4.new_notebook(cells=cells, metadata={"kernelspec": {"name": "python3", "display_name": "Python 3"}}), notebook)
    with pytest.raises(CellExecutionError, match="ZeroDivisionError") as failure:
        course.executed(notebook, inputs="x")
    assert failure.value.notebook.cells[0].outputs[0]["text"].strip() == str(tmp_path)  # run from its folder
    assert not list((tmp_path / "cache").glob("*.ipynb"))
    cells[1].source = "import matplotlib; print(matplotlib.get_backend())"
    nbformat.write(nbformat.v4.new_notebook(cells=cells, metadata={"kernelspec": {"name": "python3", "display_name": "Python 3"}}), notebook)
    run = course.executed(notebook, inputs="x")
    assert "inline" in run.cells[1].outputs[0]["text"]  # figures show although pytest sets MPLBACKEND=Agg
    assert len(list((tmp_path / "cache").glob("*.ipynb"))) == 1

    def execute_again(path):
        raise AssertionError("executed a cached lesson")

    monkeypatch.setattr(course, "execute", execute_again)
    assert course.executed(notebook, inputs="x").cells[1].outputs == run.cells[1].outputs
    with pytest.raises(AssertionError, match="executed a cached lesson"):
        course.executed(notebook, inputs="other package sources")


# --------------------------------------------------------------------------------------------------
# Quoted figures

QUOTE = re.compile(r"(?P<figure>[^\s(\[`*_]*)<!--output(?P<label>[^>]*?)-->")


def output_text(cell) -> str:
    """Everything a code cell printed or displayed as text."""
    parts = []
    for output in cell.get("outputs", []):
        if output.get("output_type") == "stream":
            parts.append("".join(output.get("text", "")))
        for kind in ("text/plain", "text/markdown", "text/html"):
            parts.append("".join(output.get("data", {}).get(kind, "")))
        if output.get("output_type") == "error":
            parts.append(f"{output.get('ename')}: {output.get('evalue')}")
    return "\n".join(parts)


def neighbours(cells, index: int) -> list:
    """The code cells around markdown cell ``index``: back to the previous markdown cell and on to
    the next one."""
    found = []
    for step in (-1, 1):
        i = index + step
        while 0 <= i < len(cells) and cells[i]["cell_type"] == "code":
            found.append(cells[i])
            i += step
    return found


def misquoted(cells) -> list[str]:
    """Each quoted figure that the code cells next to its prose did not print, as written, on a line
    that holds its label after the label."""
    problems = []
    for index, cell in enumerate(cells):
        if cell["cell_type"] != "markdown":
            continue
        source = "".join(cell["source"])
        lines = "\n".join(output_text(c) for c in neighbours(cells, index)).splitlines()
        for match in QUOTE.finditer(source):
            figure, label = match.group("figure").rstrip(".,;:"), match.group("label").strip()
            where = f"markdown cell {index}: {source[max(0, match.start() - 50):match.end()]!r}"
            if not figure or not label:
                problems.append(f"{where}: write FIGURE<!--output LABEL-->, the figure right before the comment")
                continue
            figure_re = re.compile(r"(?<![\w.])" + re.escape(figure) + r"(?!\w|\.\d)")
            if not any(label in line and figure_re.search(line, line.index(label) + len(label)) for line in lines):
                problems.append(f"{where}: no output line next to it prints {figure!r} after {label!r}")
    return problems


def quotes(cells) -> int:
    return sum(len(QUOTE.findall("".join(c["source"]))) for c in cells if c["cell_type"] == "markdown")


def test_a_figure_quoted_in_prose_must_be_in_the_outputs_next_to_it():
    """The checker itself, on a made-up lesson."""
    def code(*printed):
        return {"cell_type": "code", "source": "", "outputs": [{"output_type": "stream", "name": "stdout", "text": t} for t in printed]}

    def prose(text):
        return {"cell_type": "markdown", "source": text}

    cells = [prose("intro"), code("steps_to_90 {'transfer': 16667}\n[0, 1] radius 0.1 m\n"),
             prose("It is 16667<!--output transfer--> within 0.1<!--output radius--> m; "
                   "(56.6%<!--output 5/5-->) below."), code("5/5 interval 56.6% – 100.0%")]
    assert misquoted(cells) == [] and quotes(cells) == 3
    for wrong in ("is 0<!--output radius-->", "is 1666<!--output transfer-->", "within 0.15<!--output radius-->",
                  "within 10.1<!--output radius-->", "is <!--output transfer-->", "is 16667<!--output-->",
                  "is 16667<!--output radius-->", "is 16667<!--output 5/5-->", "is 0.1<!--output m-->"):
        cells[2] = prose(wrong)
        assert len(misquoted(cells)) == 1, wrong
    cells[2] = prose("the figures")
    cells[0] = prose("quoted too early: 16667<!--output transfer-->")  # beyond the next markdown cell
    cells.insert(1, prose("between"))
    assert len(misquoted(cells)) == 1


@pytest.mark.slow
@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_a_lesson_runs_and_says_what_it_printed(notebook):
    """The lesson runs top to bottom (its outputs go to the site's cache), and every figure its prose
    quotes is what it printed."""
    run = course.executed(notebook)  # raises, with the failing cell, if a cell fails
    cells = course.with_outputs(notebook, run)["cells"]
    assert all(c.get("execution_count") for c in cells if c["cell_type"] == "code" and c["source"].strip())
    assert misquoted(cells) == []


def test_the_site_s_tests_are_the_session_s_last(request):
    """tests/conftest.py's order: pytest-xdist hands them out last, so the build finds every lesson
    executed rather than executing, or waiting for, lessons still running on another worker."""
    items = request.session.items
    site = [i for i, item in enumerate(items) if "site" in item.fixturenames]
    if not site:
        pytest.skip("the site's tests are deselected")
    assert site == list(range(len(items) - len(site), len(items)))
    # pytest-xdist keeps that order only when it hands out one test at a time.
    assert request.config.getoption("maxschedchunk", 1) == 1


def test_the_course_quotes_figures():
    """Lessons 05, 06 and 08 quote what they print; the check above is not vacuous."""
    counts = {n.stem[:2]: quotes(json.loads(n.read_text())["cells"]) for n in NOTEBOOKS}
    assert counts["05"] >= 2 and counts["06"] >= 1 and counts["08"] >= 5, counts


# --------------------------------------------------------------------------------------------------
# The site


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links: list[tuple[str, str]] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        for name in ("id", "name"):
            if attrs.get(name) and (name == "id" or tag == "a"):
                self.ids.add(attrs[name])
        for name in ("href", "src"):
            if attrs.get(name) is not None and tag in ("a", "img", "link", "script", "source", "video", "iframe"):
                self.links.append((tag, attrs[name]))


def broken_links(site: Path) -> list[str]:
    """Every internal link and image in the site's HTML that resolves to no file in the site, or to
    an anchor that its page does not have."""
    pages = {}
    for html in site.rglob("*.html"):
        parser = _Links()
        parser.feed(html.read_text(encoding="utf-8"))
        pages[html] = parser
    broken = []
    for html, parser in pages.items():
        base = "/" + html.relative_to(site).as_posix()
        for tag, url in parser.links:
            parts = urlsplit(url)
            if parts.scheme or parts.netloc or url.startswith(("data:", "mailto:", "javascript:")):
                continue
            path = unquote(urlsplit(urljoin(base, url)).path)
            target = site / path.lstrip("/")
            if path.endswith("/") or target.is_dir():
                target = target / "index.html"
            if not target.is_file():
                broken.append(f"{html.relative_to(site)}: <{tag}> {url}")
            elif parts.fragment and target.suffix == ".html" and target in pages and parts.fragment not in pages[target].ids:
                broken.append(f"{html.relative_to(site)}: <{tag}> {url} (no such anchor)")
    return broken


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The course site, built --strict (its lessons from the cache the lesson tests filled)."""
    folder = tmp_path_factory.mktemp("site") / "site"
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(folder)],
                            cwd=ROOT, capture_output=True, text=True, timeout=1800,
                            env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert result.returncode == 0, result.stderr[-3000:]
    return folder


@pytest.mark.slow
def test_the_course_site_builds_with_strict_checks(site):
    assert (site / "course" / "00_first_drive" / "index.html").exists()
    assert "Kinematics and odometry" in (site / "index.html").read_text()


@pytest.mark.slow
def test_every_link_and_image_on_the_site_resolves(site):
    assert broken_links(site) == []


@pytest.mark.slow
@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_a_lesson_page_shows_its_outputs_and_no_stderr(site, notebook):
    page = (site / "course" / notebook.stem / "index.html").read_text(encoding="utf-8")
    assert page.count('class="jp-OutputArea-child') >= 2, "the lesson shows no outputs"
    assert re.search(r'<img [^>]*src="(data:image/png;base64,|\.\./media/[0-9a-f]+\.gif)', page), "no figure"
    assert "IPython.core.display" not in page, "a display the page cannot draw"
    body = re.sub(r"<style[^>]*>.*?</style>", "", page, flags=re.DOTALL)  # the stylesheet names stderr too
    assert 'data-mime-type="application/vnd.jupyter.stderr"' not in body and "Warning: " not in body
    assert 'href="../../stylesheets/course.css"' in page, "the stylesheet that scrolls wide tables"
    offered = json.loads((site / "course" / notebook.stem / notebook.name).read_text())  # the download
    assert all(not c.get("outputs") for c in offered["cells"]), "the page offers the site's copy, not the lesson"


@pytest.mark.slow
def test_the_first_lesson_animates_and_links_to_lesson_05(site):
    page = (site / "course" / "00_first_drive" / "index.html").read_text(encoding="utf-8")
    gif = re.search(r'<img [^>]*src="\.\./(media/[0-9a-f]+\.gif)"', page)
    assert gif, "the episode's GIF is not an image on the page"
    from PIL import Image

    with Image.open(site / "course" / gif.group(1)) as image:
        assert image.n_frames > 10  # an animation, not a still
    assert 'href="../05_rewards_and_ppo/"' in page


def test_the_link_checker_finds_a_broken_link_an_image_and_an_anchor(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "index.html").write_text('<h2 id="here">x</h2><a href="#here">ok</a><img src="../b.png">'
                                               '<a href="../b.png#x">ok</a><a href="https://example.org/">ok</a>')
    (tmp_path / "b.png").write_bytes(b"")
    (tmp_path / "index.html").write_text('<a href="a/">ok</a><a href="a/#here">ok</a><a href="c/">no</a>'
                                         '<img src="a/d.gif"><a href="a/#nowhere">no</a>')
    assert broken_links(tmp_path) == ["index.html: <a> c/", "index.html: <img> a/d.gif",
                                      "index.html: <a> a/#nowhere (no such anchor)"]

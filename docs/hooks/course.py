"""The course site's lessons with their outputs (a MkDocs hook, and the module the course tests use).

The notebooks in notebooks/ are committed without outputs. A lesson on the site shows the outputs of
one execution of its notebook, kept in ``.cache/course/``:

* the cache key is the notebook's code (its code cells, in order, and its kernel) together with
  everything an output can depend on: the package sources (common/, flatland/, physics3d/), the
  curricula and shipped policies, the images the lessons show, pyproject.toml, constraints.txt, and
  the Python and installed-distribution versions. Editing a lesson's prose re-executes nothing; editing
  a code cell or the library re-executes that lesson on the next build.
* ``executed(notebook)`` returns the executed notebook from the cache, or executes it with nbclient
  (working directory notebooks/, like Jupyter) and stores it. A file lock per lesson makes two
  processes that want the same lesson (pytest-xdist workers, a test and ``mkdocs serve``) run it once.
* the tests (tests/test_notebooks.py) call ``executed`` for every lesson: a test run fills the cache
  the site build then reads, and a site build after a green test run executes nothing.
* this hook hands mkdocs-jupyter a copy of each lesson holding the current prose and the cached
  outputs, less what does not belong on a page: stderr (warnings, progress bars, log lines) and the
  warnings and empty displays a rich progress bar leaves. A GIF (``IPython.display.Image`` of an
  animation, which the notebook exporter would print as ``<IPython.core.display.Image object>``)
  becomes a file on the site shown by an ``<img>``, so it animates. The hook also rewrites a lesson's
  relative links (``05_rewards_and_ppo.ipynb``, ``../docs/benchmarks.md``, which work in Jupyter) to
  the pages they become on the site; a link to a file not on the site is a warning, so
  ``mkdocs build --strict`` fails on it.

A first build executes every lesson (minutes); ``rm -rf .cache/course`` forces that again.
"""

from __future__ import annotations

import base64
import copy
import hashlib
import logging
import os
import re
import sys
import sysconfig
import tempfile
import time
from importlib import metadata
from pathlib import Path
from urllib.parse import urlsplit

import nbformat
from filelock import FileLock

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = ROOT / "notebooks"
CACHE = ROOT / ".cache" / "course"
# What a lesson's outputs can depend on besides its own code (files or folders, relative to ROOT).
INPUTS = ("common", "flatland", "physics3d", "curricula", "docs/images", "pyproject.toml", "constraints.txt")
SKIP = ("__pycache__", ".pyc", ".egg-info", ".nbi", ".nbc")  # build products inside the packages
RECIPE = "2"  # bump when the way a lesson is executed changes, so every cached execution is redone
CELL_TIMEOUT = 900  # seconds one cell may take

log = logging.getLogger("mkdocs.hooks.course")  # under "mkdocs": a warning fails a --strict build


# ---------------------------------------------------------------------------------------------------
# The cache


def _write(path: Path, data: bytes) -> None:
    """Write a file whole or not at all (another build or test may read it at the same time)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    partial.write_bytes(data)
    partial.replace(path)


def inputs_digest() -> str:
    """A digest of everything besides a lesson's own code that its outputs can depend on."""
    digest = hashlib.sha256(f"recipe {RECIPE}\n{sys.version}\n".encode())
    for name in INPUTS:
        path = ROOT / name
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
        for file in files:
            relative = file.relative_to(ROOT).as_posix()
            if any(part in relative for part in SKIP) or not file.exists():
                continue
            digest.update(relative.encode() + b"\0" + hashlib.sha256(file.read_bytes()).digest())
    # The installed distributions, from the environment's site-packages only: sys.path differs
    # between `mkdocs`, `python -m mkdocs` and pytest (which add the working directory and with it
    # a stray nav_curriculum.egg-info), and the same environment must give the same key.
    site_packages = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]})
    versions = sorted({f"{d.metadata['Name']}=={d.version}" for d in metadata.distributions(path=site_packages)
                       if d.metadata["Name"]})
    digest.update("\n".join(versions).encode())
    return digest.hexdigest()


def cache_key(notebook: Path, inputs: str | None = None) -> str:
    """The notebook's code and kernel, and ``inputs_digest()``: the same key, the same outputs."""
    nb = nbformat.read(notebook, as_version=4)
    digest = hashlib.sha256((inputs or inputs_digest()).encode())
    digest.update(nb.metadata.get("kernelspec", {}).get("name", "python3").encode())
    for cell in nb.cells:
        if cell.cell_type == "code":
            digest.update(b"\0cell\0" + cell.source.encode())
    return digest.hexdigest()[:20]


def cache_path(notebook: Path, inputs: str | None = None) -> Path:
    return CACHE / f"{notebook.stem}-{cache_key(notebook, inputs)}.ipynb"


def kernel_environment() -> dict[str, str]:
    """The kernel's environment: this one, less the settings that change how a lesson displays
    (pytest's MPLBACKEND=Agg would hide every figure; the kernel picks the inline backend itself)."""
    env = {k: v for k, v in os.environ.items() if k not in ("MPLBACKEND",)}
    env["PYDEVD_DISABLE_FILE_VALIDATION"] = "1"  # no debugger banner from the kernel
    return env


def execute(notebook: Path) -> nbformat.NotebookNode:
    """Execute a notebook top to bottom in a fresh kernel, from notebooks/ as Jupyter would.

    Raises ``nbclient.exceptions.CellExecutionError`` (its ``notebook`` attribute holding the outputs
    so far) if a cell fails."""
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError
    from traitlets.config import Config

    nb = nbformat.read(notebook, as_version=4)
    with tempfile.TemporaryDirectory(prefix="course-kernel-") as scratch:
        # IPC (sockets under an absolute path) rather than TCP: the kernel then prints no warning
        # about unencrypted local ports into the build's log. The client makes the kernel manager
        # from this config, so it also shuts the kernel down when the notebook is done.
        config = Config()
        config.KernelManager.transport, config.KernelManager.ip = "ipc", os.path.join(scratch, "kernel")
        client = NotebookClient(nb, config=config, timeout=CELL_TIMEOUT,
                                kernel_name=nb.metadata.get("kernelspec", {}).get("name", "python3"),
                                resources={"metadata": {"path": str(notebook.parent)}})
        # The files a lesson writes (into tempfile's folders) go under this one and leave with it:
        # a student's own run keeps them, a build or a test run does not fill /tmp.
        files = os.path.join(scratch, "files")
        os.mkdir(files)
        try:
            client.execute(env={**kernel_environment(), "TMPDIR": files})
        except CellExecutionError as error:
            error.notebook = nb
            raise
    return nb


def executed(notebook: Path, inputs: str | None = None) -> nbformat.NotebookNode:
    """The executed notebook: from the cache, or executed now and cached (once per key across
    processes). Raises as ``execute`` does if a cell fails; a failed run is not cached."""
    notebook = Path(notebook).resolve()
    path = cache_path(notebook, inputs)
    CACHE.mkdir(parents=True, exist_ok=True)
    with FileLock(str(path.with_suffix(".lock"))):
        if path.exists():
            return nbformat.read(path, as_version=4)
        began = time.perf_counter()
        log.info("course: executing %s (its outputs are cached in %s)", notebook.name, os.path.relpath(CACHE))
        nb = execute(notebook)
        nb.metadata["course"] = {"key": path.stem, "seconds": round(time.perf_counter() - began, 1)}
        _write(path, nbformat.writes(nb).encode())
        for stale in CACHE.glob(f"{notebook.stem}-*"):  # earlier executions of this lesson, old locks
            old = stale.suffix == ".ipynb" or time.time() - stale.stat().st_mtime > 3600
            if stale.stem != path.stem and stale.suffix in (".ipynb", ".lock") and old:
                stale.unlink(missing_ok=True)
        log.info("course: %s took %.0f s", notebook.name, time.perf_counter() - began)
        return nb


# ---------------------------------------------------------------------------------------------------
# A lesson as the site shows it


def with_outputs(notebook: Path, run: nbformat.NotebookNode) -> nbformat.NotebookNode:
    """The notebook as it is now (its prose may be newer than the run) with the run's outputs."""
    nb = nbformat.read(notebook, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    ran = [c for c in run.cells if c.cell_type == "code"]
    for cell, source in zip(code, ran):
        cell.outputs, cell.execution_count = copy.deepcopy(source.outputs), source.get("execution_count")
    return nb


_WARNING = re.compile(r"^\S[^\n]*:\d+: \w*Warning: ", re.MULTILINE)


def not_for_the_page(output) -> bool:
    """What a lesson page leaves out: stderr (warnings, progress bars, log lines), a warning that
    rich's console printed as a display (it takes over stderr while its progress bar is live), and
    the empty display a finished rich progress bar leaves behind."""
    if output.output_type == "stream":
        return output.name == "stderr"
    text = "".join(output.get("data", {}).get("text/plain", ""))
    if output.output_type == "display_data" and _WARNING.search(text):
        return True
    html = "".join(output.get("data", {}).get("text/html", ""))
    return output.output_type == "display_data" and not text.strip() and not re.sub(r"<[^>]*>", "", html).strip()


def for_the_site(nb: nbformat.NotebookNode, media: Path) -> tuple[nbformat.NotebookNode, list[Path]]:
    """The notebook as the site shows it, and the GIFs it shows: stderr streams (warnings, progress
    bars) dropped, and every GIF written to ``media`` and shown by an HTML ``<img>`` of that file
    (the notebook exporter draws no ``image/gif``: it would print ``<IPython.core.display.Image
    object>``). The ``<img>`` holds the file's path relative to notebooks/, as a lesson's own links do."""
    nb, gifs = copy.deepcopy(nb), []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        kept = []
        for output in cell.outputs:
            if not_for_the_page(output):
                continue
            data = output.get("data", {})
            if "image/gif" in data:
                gif = base64.b64decode(data["image/gif"])
                path = media / f"{hashlib.sha256(gif).hexdigest()[:20]}.gif"
                if not path.exists():
                    _write(path, gif)
                gifs.append(path)
                width = output.get("metadata", {}).get("image/gif", {}).get("width")
                size = f' width="{width}"' if width else ""
                output["data"] = {"text/html": f'<img src="{os.path.relpath(path, NOTEBOOKS)}"{size} alt="an animation">'}
            kept.append(output)
        cell.outputs = kept
    return nb, gifs


# ---------------------------------------------------------------------------------------------------
# The MkDocs hook

SITE_COPIES = CACHE / "site"
_notebook_pages: dict[str, Path] = {}  # src_uri of a lesson page -> the notebook in notebooks/
_sources: dict[str, object] = {}  # real path of every source file on the site -> its File


def on_files(files, config):
    """Give mkdocs-jupyter, for every lesson, a copy holding its cached outputs (executing first the
    lessons not in the cache), and put the GIFs they show on the site."""
    from mkdocs.structure.files import File

    _notebook_pages.clear()
    _sources.clear()
    lessons = []
    for file in files:
        if file.abs_src_path is None:
            continue
        real = os.path.realpath(file.abs_src_path)
        _sources[real] = file
        if file.src_uri.endswith(".ipynb") and Path(real).parent == NOTEBOOKS:
            lessons.append((file, Path(real)))
    inputs, media, shown = inputs_digest(), SITE_COPIES / "media", set()
    SITE_COPIES.mkdir(parents=True, exist_ok=True)
    for file, notebook in lessons:
        _notebook_pages[file.src_uri] = notebook
        try:
            nb = with_outputs(notebook, executed(notebook, inputs))
        except Exception as error:  # noqa: BLE001 - any failure: show what ran, and say so
            lines = re.sub(r"\x1b\[[0-9;]*m", "", str(error)).strip().splitlines()  # no terminal colours
            log.warning("course: %s failed to execute; the site shows its outputs so far (%s)", notebook.name,
                        lines[-1] if lines else type(error).__name__)
            nb = with_outputs(notebook, getattr(error, "notebook", None) or nbformat.read(notebook, as_version=4))
        site_nb, gifs = for_the_site(nb, media)
        copy_path = SITE_COPIES / notebook.name
        text = nbformat.writes(site_nb)
        if not copy_path.exists() or copy_path.read_text() != text:  # unchanged: mkdocs-jupyter's cache holds
            _write(copy_path, text.encode())
        file.abs_src_path = str(copy_path)
        for gif in gifs:
            if gif not in shown:
                shown.add(gif)
                gif_file = File.generated(config, f"{Path(file.src_uri).parent.as_posix()}/media/{gif.name}",
                                          abs_src_path=str(gif))
                files.append(gif_file)
                _sources[os.path.realpath(gif)] = gif_file
    for stale in media.glob("*.gif") if media.is_dir() else ():  # shown by no lesson for an hour
        if stale not in shown and time.time() - stale.stat().st_mtime > 3600:
            stale.unlink(missing_ok=True)
    return files


def on_post_page(output, page, config):
    """The notebook a lesson page offers for download is the lesson as committed, not the site's copy."""
    notebook = _notebook_pages.get(page.file.src_uri)
    if notebook is not None:
        offered = Path(page.file.abs_dest_path).parent / notebook.name
        if offered.exists():
            offered.write_bytes(notebook.read_bytes())
    return output


_LINK = re.compile(r'(?P<attr>\b(?:href|src))="(?P<url>[^"]*)"')


def on_page_content(html, page, config, files):
    """Rewrite a lesson's relative links to the site's pages (a link that works in Jupyter is a
    path to a file: ``05_rewards_and_ppo.ipynb``, ``../docs/benchmarks.md``)."""
    notebook = _notebook_pages.get(page.file.src_uri)
    if notebook is None:
        return html

    def rewrite(match):
        url = match.group("url")
        parts = urlsplit(url)
        if parts.scheme or parts.netloc or url.startswith(("#", "/")) or not parts.path:
            return match.group(0)
        target = os.path.realpath(os.path.join(notebook.parent, parts.path))
        file = _sources.get(target)
        if file is None:
            log.warning("course: %s links to %s, which is not on the site", notebook.name, url)
            return match.group(0)
        new = file.url_relative_to(page.file) + (f"#{parts.fragment}" if parts.fragment else "")
        return f'{match.group("attr")}="{new}"'

    return _LINK.sub(rewrite, html)

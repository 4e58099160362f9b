"""The project's promises about itself: the README's commands, CI, and declared dependencies."""

from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("common", "flatland", "physics3d")


def _readme_commands() -> list[str]:
    block = re.search(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    assert block, "the README starts with a bash block of the two set-up commands"
    return [line.strip() for line in block.group(1).splitlines() if line.strip()]


def test_readme_starts_with_the_main_job_and_the_tests_and_ci_runs_the_second():
    main_job, tests = _readme_commands()[:2]
    assert main_job.endswith("curriculum run curricula/stage1_2d.yaml") and "venv" in main_job
    assert tests.endswith("python -m pytest -n auto") and "venv" in tests
    ci = (ROOT / ".ci" / "run").read_text()
    assert tests in ci.splitlines(), "CI must run the README's test command as it is written"
    assert "rm -rf .venv" in ci, "CI must install into a new virtual environment every run"


def _names(requirements: list[str]) -> set[str]:
    return {re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].lower().replace("_", "-")
            for requirement in requirements}


def _project() -> dict:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _declared() -> set[str]:
    return _names(_project()["dependencies"])


def _third_party_imports() -> set[str]:
    names = set()
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Import):
                    names |= {alias.name.split(".")[0] for alias in node.names}
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names.add(node.module.split(".")[0])
    return {n for n in names if n not in sys.stdlib_module_names and n not in PACKAGES}


# Imported only inside optional paths, each under its extra: the IR-SIM comparison in `curriculum bench`,
# and `curriculum sweep`.
OPTIONAL = {"irsim": "irsim", "ray": "sweep", "optuna": "sweep"}


def test_optional_imports_are_declared_by_their_extra():
    extras = _project()["optional-dependencies"]
    for module, extra in OPTIONAL.items():
        providers = {d.lower().replace("_", "-")
                     for d in importlib.metadata.packages_distributions().get(module, [module.replace("_", "-")])}
        assert providers & _names(extras[extra]), f"{module} is not in the [{extra}] extra"


def test_every_package_the_code_imports_is_a_declared_dependency():
    distributions = importlib.metadata.packages_distributions()
    declared = _declared()
    missing = {}
    for module in _third_party_imports() - set(OPTIONAL):
        providers = {d.lower().replace("_", "-") for d in distributions.get(module, [module])}
        if not providers & declared:
            missing[module] = sorted(providers)
    assert not missing, f"imported but not in pyproject's dependencies: {missing}"


def test_what_stable_baselines3_needs_for_our_runs_is_declared():
    # A run logs to TensorBoard and shows SB3's progress bar: SB3 imports these only then, so a
    # missing one passed every import check and failed a new user's first run.
    assert {"tensorboard", "tqdm", "rich"} <= _declared()


def test_every_module_with_cached_kernels_is_watched_for_source_changes():
    from common.kernel_cache import KERNEL_MODULES

    # A register_jitable function is compiled into its callers' cached kernels: its module is watched too.
    cached = {str(path.relative_to(ROOT)) for package in PACKAGES for path in (ROOT / package).rglob("*.py")
              if re.search(r"@njit\([^)]*cache=True|@register_jitable", path.read_text())}
    assert cached == set(KERNEL_MODULES)


def test_a_changed_kernel_source_clears_the_stale_compiled_kernels(tmp_path):
    # numba would load a kernel compiled against a callee's old source: refresh() must delete it.
    from common.kernel_cache import refresh

    modules = ("common/geometry.py", "common/occupancy.py")
    for module in modules:
        (tmp_path / module).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / module).write_text("def f(): return 1\n")
    cache = tmp_path / "common" / "__pycache__"
    cache.mkdir()

    def compiled() -> list[Path]:
        for name in ("occupancy._rasterise-131.py311.nbi", "occupancy._rasterise-131.py311.1.nbc"):
            (cache / name).touch()
        return sorted(cache.glob("*.nb?"))

    other = cache / "occupancy.cpython-311.pyc"
    other.touch()
    assert refresh(tmp_path, modules) and not list(cache.glob("*.nb?"))  # no record yet: cleared
    kept = compiled()
    assert not refresh(tmp_path, modules) and sorted(cache.glob("*.nb?")) == kept  # unchanged: kept
    (tmp_path / "common" / "geometry.py").write_text("def f(): return 2\n")  # a callee's module changes
    assert refresh(tmp_path, modules) and not list(cache.glob("*.nb?")) and other.exists()
    compiled()
    assert not refresh(tmp_path, modules) and len(list(cache.glob("*.nb?"))) == 2

"""The project's promises about itself: the README's commands, CI, and declared dependencies."""

from __future__ import annotations

import ast
import importlib.metadata
import os
import re
import subprocess
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
# `curriculum sweep`, and ONNX policies (onnx checks a file's graph before onnxruntime runs it; torch's
# exporter imports onnx and onnxscript itself).
OPTIONAL = {"irsim": "irsim", "ray": "sweep", "optuna": "sweep", "onnxruntime": "onnx", "onnx": "onnx"}


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

    # A register_jitable (or uncounted) function is compiled into its callers' cached kernels: its
    # module is watched too.
    cached = {str(path.relative_to(ROOT)) for package in PACKAGES for path in (ROOT / package).rglob("*.py")
              if re.search(r"@kernel\b|@register_jitable|@uncounted\b", path.read_text())
              and path.name != "kernel_cache.py"}
    assert cached == set(KERNEL_MODULES)


def test_a_kernel_compiled_against_a_callees_old_source_is_not_loaded_from_the_cache(tmp_path):
    # numba stamps a cached kernel with its own file only: after the callee alone changed, plain
    # njit(cache=True) loads the old machine code and returns the old value.
    (tmp_path / "callee.py").write_text("from numba.extending import register_jitable\n\n\n"
                                        "@register_jitable\ndef value():\n    return 1\n")
    (tmp_path / "caller.py").write_text(
        "from pathlib import Path\nfrom common.kernel_cache import cached_kernels\nfrom callee import value\n\n"
        "kernel = cached_kernels(Path(__file__).parent, ('callee.py', 'caller.py'))\n\n\n"
        "@kernel\ndef run():\n    return value()\n")
    program = "import caller; print(caller.run(), caller.run.stats.cache_hits.total())"

    def run() -> list[str]:
        done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, cwd=tmp_path, check=True,
                              env={**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"})
        return done.stdout.split()

    assert run() == ["1", "0"]  # compiled and cached
    assert run() == ["1", "1"]  # loaded from the cache: it is used
    (tmp_path / "callee.py").write_text((tmp_path / "callee.py").read_text().replace("return 1", "return 2"))
    assert run() == ["2", "0"]  # the callee changed: recompiled, not loaded


def test_a_kernels_machine_code_for_fixed_types_is_the_cached_kernel(tmp_path):
    # compiled_for skips the dispatcher's type matching: it must be the same kernel (same value,
    # from the same stamped cache), not a second compilation.
    (tmp_path / "scaled.py").write_text(
        "from pathlib import Path\nfrom common.kernel_cache import cached_kernels\n\n"
        "kernel = cached_kernels(Path(__file__).parent, ('scaled.py',))\n\n\n"
        "@kernel\ndef total(values, scale):\n    return values.sum() * scale\n")
    program = ("import numpy as np, scaled\nfrom common.kernel_cache import compiled_for\n"
               "values = np.arange(4.0)\nrun = compiled_for(scaled.total, values, 2.0)\n"
               "machine = [o.entry_point for o in scaled.total.overloads.values()]\n"
               "print(run(values, 3.0), scaled.total(values, 3.0), machine == [run], scaled.total.stats.cache_hits.total())")

    def run() -> list[str]:
        done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, cwd=tmp_path, check=True,
                              env={**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"})
        return done.stdout.split()

    assert run() == ["18.0", "18.0", "True", "0"]  # the kernel's one compilation, made by compiled_for
    assert run() == ["18.0", "18.0", "True", "1"]  # loaded from the kernel's cache


def test_a_static_world_does_not_compile_the_movers_kernels():
    # The movers' scan took 6 of a static world's 40 s first build from an empty cache.
    program = ("import gymnasium as gym, numpy as np, flatland\nfrom flatland.lidar import cast_scan_among\n"
               "env = gym.make('flatland/Nav-v0', world='sparse')\nenv.reset(seed=0)\nenv.step(env.action_space.sample())\n"
               "print(len(cast_scan_among.overloads))\n"
               "env.unwrapped.world.lidar.scan(1.0, 1.0, 0.0, np.array([[2.0, 1.0, 0.3]]), np.empty((0, 6)))  # a mover\n"
               "print(len(cast_scan_among.overloads))")
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, check=True, cwd=ROOT)
    assert done.stdout.split() == ["0", "1"]


def test_importing_the_packages_writes_nothing(tmp_path):
    import shutil

    copy = tmp_path / "project"
    for package in PACKAGES:
        shutil.copytree(ROOT / package, copy / package, ignore=shutil.ignore_patterns("__pycache__"))

    def files() -> dict[str, float]:
        return {str(p.relative_to(copy)): p.stat().st_mtime for p in copy.rglob("*")}

    before = files()
    subprocess.run([sys.executable, "-c", "import common, common.occupancy, common.evaluation, flatland, physics3d"],
                   check=True, cwd=copy, env={**os.environ, "PYTHONPATH": str(copy), "PYTHONDONTWRITEBYTECODE": "1"})
    assert files() == before

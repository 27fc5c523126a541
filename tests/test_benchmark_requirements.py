"""docs/usage.md installs the benchmarks with ``pip install -e '.[bench]'``: every third-party
module the scripts import, directly or through the project's own modules, must come with the
project's dependencies and its ``bench`` extra (the ``dev`` extra is not installed then)."""

from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
import tomllib

from packaging.requirements import Requirement

from tests.conftest import REPO_ROOT

PROJECT_PACKAGES = {"tracking", "service", "api_schemas", "devtools", "benchmarks", "tests"}


def _imported(path) -> set[str]:
    """Dotted names of the modules ``path`` imports (anywhere in the file)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _module_file(name: str):
    base = REPO_ROOT.joinpath(*name.split("."))
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _third_party_imports() -> set[str]:
    """Top-level third-party modules reached from the benchmark scripts (not ``peers/``, which
    run in their own environments)."""
    todo = list((REPO_ROOT / "benchmarks").glob("*.py"))
    seen, outside = set(todo), set()
    while todo:
        for name in _imported(todo.pop()):
            top = name.split(".")[0]
            local = _module_file(f"benchmarks.{top}") if top.startswith("_") else None
            if top in PROJECT_PACKAGES or local is not None:
                path = local or _module_file(name)
                if path is not None and path not in seen:
                    seen.add(path)
                    todo.append(path)
            elif top not in sys.stdlib_module_names and top != "__future__":
                outside.add(top)
    return outside


# import names of distributions named otherwise, for when the distribution is not installed
# here (CI installs the dev extra only, without matplotlib and pillow)
KNOWN_PROVIDERS = {"PIL": "pillow", "cv2": "opencv-python-headless", "zenoh": "eclipse-zenoh"}


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _closure(requirements: list[str]) -> set[str]:
    """Normalised names of the distributions ``requirements`` install: the requirements, and
    the dependencies of those installed here (so a module must come from a declared
    requirement unless its provider is a dependency of an installed one)."""
    names, todo = set(), [Requirement(r) for r in requirements]
    while todo:
        requirement = todo.pop()
        name = _normal(requirement.name)
        if name in names:
            continue
        names.add(name)
        try:
            dependencies = importlib.metadata.requires(name) or []
        except importlib.metadata.PackageNotFoundError:
            continue
        for extra in requirement.extras or {""}:
            for dependency in dependencies:
                parsed = Requirement(dependency)
                if parsed.marker is None or parsed.marker.evaluate({"extra": extra}):
                    todo.append(parsed)
    return names


def test_the_bench_extra_installs_every_module_the_benchmarks_import():
    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]
    installed = _closure(project["dependencies"] + project["optional-dependencies"]["bench"])
    installed_providers = importlib.metadata.packages_distributions()
    providers = {
        module: installed_providers.get(module) or [KNOWN_PROVIDERS.get(module, module)]
        for module in _third_party_imports()
    }
    missing = {
        module: names
        for module, names in providers.items()
        if not any(_normal(name) in installed for name in names)
    }
    assert not missing, f"imported by the benchmarks, not installed by '.[bench]': {missing}"

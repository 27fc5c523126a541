"""The packages' layers: which package may import which.

``tracking`` (the algorithms) knows nothing of HTTP or the service; ``api_schemas`` (the API's
models) no algorithm; ``tracking.datasets`` (file readers) neither the detectors nor the
evaluation, and the detectors not the evaluation, so ``tracking.detection`` and
``tracking.evaluation`` do not import each other; the installed packages nothing of the
checkout's ``devtools``, ``tests`` or ``benchmarks`` (``pip install .`` ships none of them).

Each case imports every module of a package in a fresh interpreter and reads ``sys.modules``, so
the imports of other tests do not count.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from fnmatch import fnmatch

import pytest

from tests.conftest import REPO_ROOT

CHECKOUT_ONLY = ("devtools", "tests", "benchmarks")

# package -> top-level or dotted module names that importing all of it must not load
LAYERS = {
    "tracking": ("service", "api_schemas", "fastapi", "starlette", *CHECKOUT_ONLY),
    "api_schemas": ("tracking", "service", *CHECKOUT_ONLY),
    "service": CHECKOUT_ONLY,
    "tracking.datasets": ("tracking.detection", "tracking.evaluation"),
    "tracking.detection": ("tracking.evaluation",),
}

# Imports every module of a package (``__main__`` modules run their command: skipped) and
# prints the names in sys.modules.
_IMPORT_ALL = """
import importlib, json, pkgutil, sys
package = importlib.import_module(sys.argv[1])
for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
    if info.name.rsplit(".", 1)[-1] != "__main__":
        importlib.import_module(info.name)
print(json.dumps(sorted(sys.modules)))
"""


def _loaded(forbidden: str, modules: list[str]) -> list[str]:
    return [m for m in modules if m == forbidden or m.startswith(forbidden + ".")]


@pytest.mark.parametrize("package", sorted(LAYERS))
def test_a_package_imports_only_the_layers_below_it(package: str):
    done = subprocess.run(
        [sys.executable, "-c", _IMPORT_ALL, package],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    modules = json.loads(done.stdout.splitlines()[-1])
    assert package in modules
    loaded = {name: _loaded(name, modules) for name in LAYERS[package]}
    assert not any(loaded.values()), f"importing {package} loads {loaded}"


def test_the_installed_packages_are_the_product_only():
    """``pip install .`` ships the packages whose names match ``[tool.setuptools.packages.find]``
    ``include`` (fnmatch patterns, as setuptools reads them): the three packages, not the tool
    and test support beside them."""
    config = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())
    include = config["tool"]["setuptools"]["packages"]["find"]["include"]
    top_level = {p.parent.name for p in REPO_ROOT.glob("*/__init__.py")}
    shipped = {name for name in top_level if any(fnmatch(name, rule) for rule in include)}
    assert shipped == {"tracking", "service", "api_schemas"}
    assert {"devtools", "tests"} <= top_level - shipped

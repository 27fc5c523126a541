"""The benchmarks' check, before they measure anything, that they can draw what was asked."""

from __future__ import annotations

import argparse
import importlib


def require_drawing(parser: argparse.ArgumentParser, option: str, *modules: str) -> None:
    """Stop with a usage error naming ``option`` unless every one of ``modules`` imports.

    The pictures and plots need the ``bench`` extra (matplotlib, Pillow), which the test set-up
    does not install; without this check a run would measure for half an hour and then lose its
    figures to the ImportError of the drawing step at its end.
    """
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:
            parser.error(
                f"{option} needs the Python package {module!r}: install the benchmark extras "
                "(pip install -e '.[bench]') or leave the option out"
            )

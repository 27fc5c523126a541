"""``vtrack models fetch`` and ``vtrack models list``: the CNN model files, downloaded on purpose
and verified (the service itself never downloads)."""

from __future__ import annotations

import argparse
import os
import sys
import textwrap
from pathlib import Path

from service.argument_types import number_type
from service.models.catalog import (
    CATALOG,
    DEFAULT_DETECTOR,
    DEFAULT_MODELS,
    DEFAULT_POSE,
    DEFAULT_REID,
    OMZ_HUMAN_RIGHTS_NOTICE,
    OMZ_LICENCE,
    check_name,
)

MODELS_DIR_VARIABLE = "VTRACK_MODELS_DIR"
"""The service's setting for the models folder; also the default of ``--dir`` here."""

DEFAULT_MODELS_DIR = Path("models")
"""``--dir`` without the variable: ``models`` in the current folder."""

LICENCE_NOTICE = (
    f"These are Intel Open Model Zoo models, licensed under {OMZ_LICENCE}. Open Model Zoo's "
    f'README adds: "{OMZ_HUMAN_RIGHTS_NOTICE}"'
)
"""Printed once by every ``vtrack models fetch``: whoever fetches the files is told the terms
before using them."""


def add_command(commands: argparse._SubParsersAction) -> None:
    """The ``models`` command, its ``fetch`` and ``list`` subcommands and their arguments."""
    models = commands.add_parser(
        "models",
        help="fetch and list the CNN model files (Intel Open Model Zoo)",
        description="The CNN models the service knows (Intel Open Model Zoo, Apache-2.0): "
        "download them on purpose, every file's size and sha256 checked, and list what a "
        "models folder holds. The service never downloads.",
    )
    actions = models.add_subparsers(dest="models_command", required=True, metavar="ACTION")
    fetch = actions.add_parser(
        "fetch",
        help="download model files into a models folder, verified",
        description="Download the files of the named models into the models folder, "
        "<model>/<precision>/<file> as Open Model Zoo lays them out. A file already there "
        "with the right size and sha256 is left alone; a damaged one is replaced; a download "
        "that fails any check leaves nothing behind.",
    )
    fetch.add_argument(
        "names",
        nargs="*",
        metavar="NAME",
        help=f"catalog models (default: {', '.join(DEFAULT_MODELS)}, the networks a job runs "
        "by default; 'vtrack models list' shows the catalog)",
    )
    fetch.add_argument("--all", action="store_true", help="every model of the catalog")
    _add_dir_argument(fetch)
    fetch.add_argument(
        "--mirror",
        metavar="URL",
        help="fetch from this mirror instead of Open Model Zoo's storage: <URL>/<model>/"
        "<precision>/<file>; an http(s) or file URL, or a folder laid out like a models folder "
        "(for a site without internet access)",
    )
    fetch.add_argument(
        "--timeout",
        type=number_type(float, 0, above=True),
        default=60.0,
        metavar="SECONDS",
        help="give up on a server silent for this long (default 60)",
    )
    fetch.set_defaults(handler=_fetch)
    listing = actions.add_parser(
        "list",
        help="the catalog, and which models a models folder holds verified",
        description="One line per catalog model: name, task, size, and whether all its files "
        "are in the models folder with the right size and sha256 (present), none are "
        "(missing), some are (incomplete), or one is damaged (corrupt).",
    )
    _add_dir_argument(listing)
    listing.set_defaults(handler=_list)


def _add_dir_argument(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--dir",
        type=Path,
        metavar="DIR",
        help=f"the models folder ({MODELS_DIR_VARIABLE}, default: {DEFAULT_MODELS_DIR}/ in "
        "the current folder)",
    )


def _models_dir(given: Path | None) -> tuple[Path, str]:
    """The models folder of ``--dir``, else of the variable, else the default (absolute, so
    the setting printed works from anywhere), and where it came from, for messages."""
    if given is not None:
        return given.absolute(), "--dir"
    value = os.environ.get(MODELS_DIR_VARIABLE, "")
    if value:
        return Path(value).absolute(), MODELS_DIR_VARIABLE
    return DEFAULT_MODELS_DIR.absolute(), "the default models folder"


def _fetch(args: argparse.Namespace) -> int:
    from service.models.fetch import FetchResult, ModelFetchError, fetch_models, mirror_base

    if args.all and args.names:
        print("vtrack: give model names or --all, not both", file=sys.stderr)
        return 2
    names = list(CATALOG) if args.all else args.names or list(DEFAULT_MODELS)
    try:
        for name in names:  # every name checked before anything is downloaded
            check_name(name)
        if args.mirror is not None:
            mirror_base(args.mirror)
    except ValueError as error:  # an unknown name (UnknownModelError), a mirror that is none
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    models_dir, origin = _models_dir(args.dir)
    try:
        models_dir.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        reason = error.strerror or str(error)
        print(f"vtrack: {origin}: cannot create {models_dir}: {reason}", file=sys.stderr)
        return 2
    print(textwrap.fill(LICENCE_NOTICE, width=100), flush=True)

    def report(result: FetchResult) -> None:
        if result.action == "present":
            said = "already present (size and sha256 verified)"
        elif result.action == "replaced":
            said = f"replaced a corrupt copy (downloaded {result.received} bytes)"
        else:
            said = f"downloaded {result.received} bytes"
        print(f"{result.file.path}: {said}", flush=True)  # as it happens: downloads take time

    try:
        fetch_models(names, models_dir, mirror=args.mirror, timeout=args.timeout, progress=report)
    except ModelFetchError as error:
        hint = ""
        if args.mirror is None and error.problem.startswith("cannot connect"):
            hint = "; without internet access, --mirror fetches from a copy (docs/detection.md)"
        print(f"vtrack: {error}{hint}", file=sys.stderr)
        return 1
    print(f"models in {models_dir}; the service finds them with {MODELS_DIR_VARIABLE}={models_dir}")
    return 0


def _list(args: argparse.Namespace) -> int:
    from service.models.fetch import model_state

    models_dir, _ = _models_dir(args.dir)
    name_width = max(len(name) for name in CATALOG)
    task_width = max(len(model.task) for model in CATALOG.values())
    present = 0
    for name, model in CATALOG.items():
        state = model_state(models_dir, name)
        present += state == "present"
        default = _DEFAULT_ROLES.get(name, "")
        print(
            f"{name:<{name_width}}  {model.task:<{task_width}}  "
            f"{model.size / 1e6:4.1f} MB  {state}{default}"
        )
    where = models_dir if models_dir.is_dir() else f"{models_dir} (no such folder)"
    print(f"{present} of {len(CATALOG)} present and verified in {where}")
    return 0


_DEFAULT_ROLES = {
    DEFAULT_DETECTOR: "  (default detector)",
    DEFAULT_POSE: "  (default pose)",
    DEFAULT_REID: "  (default re-identification)",
}

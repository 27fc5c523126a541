"""Downloading the catalog's model files on purpose, every byte checked.

The runtime never downloads (``tracking/`` does not import this): a user runs ``vtrack models
fetch`` once, or the Docker build does, and the service then loads the files from the folder.

Each file is streamed into a temporary file beside its place, its size and sha256 (and OMZ's
sha384 where the catalog has it) checked, and only then renamed into place (``os.replace``,
atomic within a folder). A file that fails any check, or whose download breaks, leaves nothing
behind, so a models folder holds verified files or none: a half-written ``.bin`` would otherwise
load and detect nothing, or fail deep inside OpenVINO with a message that names no download.
"""

from __future__ import annotations

import hashlib
import http.client
import os
import secrets
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Literal

from service import __version__
from service.models.catalog import CatalogModel, ModelFile, check_name

__all__ = [
    "CHUNK_SIZE",
    "FetchResult",
    "FileState",
    "ModelFetchError",
    "ModelState",
    "fetch_models",
    "file_state",
    "mirror_base",
    "model_state",
    "source_url",
]

CHUNK_SIZE = 256 * 1024
"""Most bytes read (from the network or a file) at a time: few system calls for the
multi-megabyte ``.bin`` files, little memory."""

Action = Literal["downloaded", "present", "replaced"]
FileState = Literal["present", "missing", "corrupt"]
ModelState = Literal["present", "missing", "incomplete", "corrupt"]


class ModelFetchError(ValueError):
    """A file that could not be fetched: the server's answer, the connection or the bytes
    received were wrong (or the models folder could not be written). Nothing of that file was
    left in the models folder; a copy that was there before is as it was.

    Attributes
    ----------
    path:
        The file, relative to the models folder.
    url:
        Where it was fetched from.
    problem:
        What went wrong.
    """

    def __init__(self, path: str, url: str, problem: str) -> None:
        self.path, self.url, self.problem = path, url, problem
        super().__init__(f"{path} from {url}: {problem}")


@dataclass(frozen=True, slots=True)
class FetchResult:
    """What :func:`fetch_models` did with one file.

    Attributes
    ----------
    model:
        The catalog name of the model the file belongs to.
    file:
        The catalog's entry.
    path:
        Where the file now is.
    action:
        ``"present"``: a verified copy was there, left alone; ``"downloaded"``: there was none;
        ``"replaced"``: the copy there had the wrong size or checksum, a verified one took its
        place.
    received:
        Bytes downloaded (0 when present).
    url:
        Where it was downloaded from; ``None`` when present.
    """

    model: str
    file: ModelFile
    path: Path
    action: Action
    received: int = 0
    url: str | None = None


def mirror_base(mirror: str) -> str:
    """The base URL of a mirror given as a URL (``http://``, ``https://``, ``file://``) or as a
    local folder laid out like a models folder; raises ValueError for anything else."""
    if "://" in mirror:
        scheme = urllib.parse.urlsplit(mirror).scheme.lower()
        if scheme not in ("http", "https", "file"):
            raise ValueError(f"mirror {mirror!r}: expected an http, https or file URL, or a folder")
        return mirror.rstrip("/")
    folder = Path(mirror)
    if not folder.is_dir():
        raise ValueError(
            f"mirror {mirror!r} is neither a folder nor a URL (http://, https://, file://)"
        )
    return folder.resolve().as_uri()


def source_url(file: ModelFile, mirror: str | None = None) -> str:
    """Where ``file`` is fetched from: OMZ's storage, or ``<mirror>/<relative path>``."""
    if mirror is None:
        return file.url
    return f"{mirror_base(mirror)}/{urllib.parse.quote(file.path)}"


def _digests(path: Path, file: ModelFile) -> tuple[str, str | None]:
    """sha256 and (where the catalog has one) sha384 of the file at ``path``."""
    sha256 = hashlib.sha256()
    sha384 = hashlib.sha384() if file.sha384 else None
    with path.open("rb") as source:
        while chunk := source.read(CHUNK_SIZE):
            sha256.update(chunk)
            if sha384 is not None:
                sha384.update(chunk)
    return sha256.hexdigest(), sha384.hexdigest() if sha384 is not None else None


def file_state(path: Path, file: ModelFile) -> FileState:
    """Whether ``path`` holds the catalog's ``file``: ``"present"`` (size and checksums
    right), ``"missing"``, or ``"corrupt"`` (wrong size or checksum, not a file, unreadable)."""
    try:
        if not path.is_file():
            return "corrupt" if path.exists() else "missing"
        if path.stat().st_size != file.size:
            return "corrupt"  # no need to read it
        sha256, sha384 = _digests(path, file)
    except OSError:  # unreadable: not a copy anything can load
        return "corrupt"
    return "present" if (sha256, sha384) == (file.sha256, file.sha384) else "corrupt"


def model_state(models_dir: Path, name: str) -> ModelState:
    """Whether model ``name`` is complete and verified in ``models_dir``: ``"present"``,
    ``"missing"`` (no file of it), ``"incomplete"`` (some files missing, the others right) or
    ``"corrupt"`` (a file of the wrong size or checksum). Raises UnknownModelError."""
    model = check_name(name)
    states = {file_state(Path(models_dir) / f.path, f) for f in model.files}
    if "corrupt" in states:
        return "corrupt"
    if states == {"present"}:
        return "present"
    return "missing" if states == {"missing"} else "incomplete"


def fetch_models(
    names: Iterable[str],
    models_dir: Path,
    *,
    mirror: str | None = None,
    timeout: float = 60,
    progress: Callable[[FetchResult], None] | None = None,
) -> list[FetchResult]:
    """Download every file of the models ``names`` into ``models_dir/<path>``, verified.

    Parameters
    ----------
    names:
        Catalog names (:data:`~service.models.catalog.CATALOG`), or one name; all are checked
        before any download. A name given twice is fetched once.
    models_dir:
        The models folder; created if need be.
    mirror:
        Instead of OMZ's storage, fetch each file from ``<mirror>/<relative path>``: a URL
        (http, https, file) or a folder laid out like a models folder (a site without internet
        access serves or mounts one).
    timeout:
        Seconds to wait for the connection and for each read; a server silent for longer
        fails the file.
    progress:
        Called with each file's result as soon as it is settled (the command line prints a
        line for each).

    Returns
    -------
    One result per file, in the order fetched: a model's weights before its graph, so that its
    ``.xml`` (the file a detector is given) appears only once the ``.bin`` is in place.

    Raises
    ------
    UnknownModelError
        A name not in the catalog (nothing fetched).
    ValueError
        A ``mirror`` that is neither a URL nor a folder (nothing fetched).
    ModelFetchError
        A file that failed (HTTP error, refused, dropped or silent connection, wrong size or
        checksum, or a models folder that cannot be written): nothing of it was left behind;
        the files settled before it stay.
    """
    if isinstance(names, str):  # one name, not its letters
        names = [names]
    models: list[CatalogModel] = [check_name(name) for name in dict.fromkeys(names)]
    if mirror is not None:
        mirror_base(mirror)  # a bad mirror before anything is fetched
    models_dir = Path(models_dir)
    results = []
    for model in models:
        for file in sorted(model.files, key=lambda f: f.path == model.graph):
            target = models_dir / file.path
            state = file_state(target, file)
            if state == "present":
                result = FetchResult(model.name, file, target, "present")
            else:
                url = source_url(file, mirror)
                received = _download(file, url, target, timeout)
                action: Action = "replaced" if state == "corrupt" else "downloaded"
                result = FetchResult(model.name, file, target, action, received, url)
            results.append(result)
            if progress is not None:
                progress(result)
    return results


def _download(file: ModelFile, url: str, target: Path, timeout: float) -> int:
    """Fetch ``url`` into ``target`` through a temporary file beside it, verified against
    ``file``; returns the bytes received. Raises ModelFetchError, leaving nothing behind."""
    temp: Path | None = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        temp, out = _temporary_beside(target)
        with out:
            received = _receive(file, url, timeout, out)
            out.flush()
            os.fsync(out.fileno())  # the bytes on disk before the name points at them
        sha256, sha384 = _digests(temp, file)  # as written, not as received
        if sha256 != file.sha256:
            raise ModelFetchError(
                file.path,
                url,
                f"sha256 mismatch: got {sha256}, expected {file.sha256} (all {received} bytes "
                "received: a different or damaged file)",
            )
        if sha384 != file.sha384:
            raise ModelFetchError(
                file.path, url, f"sha384 mismatch: got {sha384}, expected {file.sha384}"
            )
        os.replace(temp, target)
        temp = None
        return received
    except OSError as error:  # the network's OSErrors are ModelFetchErrors by now
        where = error.filename or target.parent
        raise ModelFetchError(
            file.path, url, f"cannot write {where}: {error.strerror or error}"
        ) from error
    finally:
        if temp is not None:
            temp.unlink(missing_ok=True)


def _temporary_beside(target: Path) -> tuple[Path, BinaryIO]:
    """A new hidden ``.part`` file in the target's folder (the same file system, so that
    ``os.replace`` is a rename) and its open handle. Created with the default permissions
    (``0o666`` less the umask), unlike ``tempfile``'s ``0o600``: a file fetched by root at image
    build time must be readable by the service's user."""
    while True:
        temp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.part")
        try:
            descriptor = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:  # another fetch's, by a one in four billion chance
            continue
        return temp, os.fdopen(descriptor, "wb")


def _receive(file: ModelFile, url: str, timeout: float, out: BinaryIO) -> int:
    """Stream ``url`` into ``out``; returns the bytes received, exactly ``file.size``.
    Raises ModelFetchError for what the server or the network did wrong (``out``'s own write
    errors pass as OSError)."""
    request = urllib.request.Request(url, headers={"User-Agent": f"vtrack/{__version__}"})
    expected = file.size

    def failed(problem: str) -> ModelFetchError:
        return ModelFetchError(file.path, url, problem)

    try:
        response = urllib.request.urlopen(request, timeout=timeout)  # follows redirects
    except urllib.error.HTTPError as error:
        error.close()
        raise failed(f"HTTP {error.code} {error.reason}") from None
    except urllib.error.URLError as error:  # refused, no such host, a file:// path missing...
        raise failed(f"cannot connect: {_reason(error.reason, timeout)}") from None
    except (OSError, http.client.HTTPException) as error:  # connected, then no proper answer
        raise failed(f"no answer: {_reason(error, timeout)}") from None
    received = 0
    with response:
        announced = response.headers.get("Content-Length")
        if announced is not None and announced.strip().isdigit() and int(announced) != expected:
            raise failed(f"the server announces {int(announced)} bytes, expected {expected}")
        while True:
            try:
                chunk = response.read1(CHUNK_SIZE)  # what has arrived: exact counts
            except (OSError, http.client.HTTPException) as error:
                raise failed(
                    f"the download broke after {received} of {expected} bytes: "
                    f"{_reason(error, timeout)}"
                ) from None
            if not chunk:
                break
            received += len(chunk)
            if received > expected:
                raise failed(f"more than the expected {expected} bytes received")
            out.write(chunk)
    if received < expected:
        # http.client ends a body cut short as if it were complete: the count tells
        raise failed(f"the connection closed after {received} of {expected} bytes")
    return received


def _reason(error: object, timeout: float) -> str:
    """A network error in words: a timeout says how long was waited."""
    if isinstance(error, TimeoutError):
        return f"no data within {timeout:g} s (timed out)"
    if isinstance(error, OSError) and error.strerror:
        return error.strerror
    return str(error) or type(error).__name__

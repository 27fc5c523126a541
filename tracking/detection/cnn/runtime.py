"""OpenVINO inference for the CNN detectors: a model read once, compiled once per input shape.

OpenVINO (Apache-2.0) runs Open Model Zoo IR pairs (``.xml`` graph + ``.bin`` weights beside it)
and ONNX files on the CPU. A worker process reads each model file once and compiles it once for
each input shape it is asked for (a video's frames all have one shape; batches of regions of
interest or crops a few), so :func:`load_network` keeps what it loaded for the life of the
process. A whole frame runs as one request on every thread (latency mode); batches of crops as
two requests at once, one per CPU stream (:meth:`Network.infer_batches`).
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["MODEL_SUFFIXES", "CnnModelError", "Network", "load_network"]

MODEL_SUFFIXES = (".xml", ".onnx")
"""Model files the runtime reads: OpenVINO IR (with its ``.bin`` beside it) and ONNX."""

_MAX_SHAPES = 8  # compiled shapes kept per model: the frame's, a few batch sizes of crops
_STREAMS = 2  # concurrent requests of Network.infer_batches (see there)


class CnnModelError(ValueError):
    """A file is not a model the CNN detector can run (missing, corrupt, wrong outputs)."""


@dataclass(slots=True)
class Network:
    """One model file on the CPU: its single image input and its outputs, compiled per shape.

    Attributes
    ----------
    path:
        The ``.xml`` or ``.onnx`` file.
    threads:
        Inference threads (OpenVINO's ``INFERENCE_NUM_THREADS``); 0: the runtime's choice.
    input_shape:
        The model's own input shape ``(N, C, H, W)``.
    output_shapes:
        The shape of each output, -1 for a dimension that follows the input (SSD's
        ``[1, 1, N, 7]``, YOLOX's head ``[1, A, 5 + classes]``, OpenPose's heatmaps and PAFs).
    reshapeable:
        Whether the model compiles at other input sizes and batch sizes.
    """

    path: Path
    threads: int
    input_shape: tuple[int, int, int, int]
    output_shapes: tuple[tuple[int, ...], ...]
    reshapeable: bool
    _model: Any = field(repr=False)  # an openvino.Model (OpenVINO ships no types)
    _compiled: OrderedDict = field(default_factory=OrderedDict, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    @property
    def name(self) -> str:
        """The model's name: its file's stem (``person-detection-0202``)."""
        return self.path.stem

    @property
    def output_rank(self) -> int:
        """Dimensions of the first output (4 for SSD's, 3 for YOLOX's head)."""
        return len(self.output_shapes[0])

    def infer(self, batch: np.ndarray) -> np.ndarray:
        """The first output for ``batch`` (:meth:`infer_all`)."""
        return self.infer_all(batch)[0]

    def infer_all(self, batch: np.ndarray) -> list[np.ndarray]:
        """Every output, in the model's order, for ``batch`` ``(N, 3, H, W)`` float32; compiles
        the shape on first use (a non-reshapeable model takes its own shape only). Each call
        makes its own inference request (a few microseconds), so threads may share a model."""
        shape = tuple(int(n) for n in batch.shape)
        if not self.reshapeable and shape != self.input_shape:
            raise ValueError(f"{self.path.name} takes input {self.input_shape} only, got {shape}")
        compiled = self._compiled_for(shape)
        request = compiled.create_infer_request()
        # the batch is wrapped, not copied (it is the caller's, alive until infer returns)
        request.infer({0: np.ascontiguousarray(batch, dtype=np.float32)}, share_inputs=True)
        return [
            np.array(request.get_output_tensor(i).data, copy=True)
            for i in range(len(compiled.outputs))
        ]

    def infer_batches(self, inputs: np.ndarray, max_batch: int) -> list[np.ndarray]:
        """Every output for ``inputs`` ``(N, 3, H, W)``, concatenated over ``N``.

        The inputs go as :data:`_STREAMS` requests of one size at a time, each at most
        ``max_batch`` (a model of fixed shape: its own batch size), run at once on as many CPU
        streams (OpenVINO's throughput mode), the last request padded. A small network on a
        small batch keeps one core busy per request better than cores share one request:
        6 re-identification crops took 7.2 ms as two requests of 3 against 11.6 ms as
        batches of 4 and 2 on one stream of two threads, 6 pose crops 5.7 against 7.2 ms.
        """
        count = len(inputs)
        if count == 0:
            raise ValueError("infer_batches needs at least one input")
        size = self.input_shape[0]
        if self.reshapeable:  # the streams share the inputs: ceil(count / streams) each
            size = min(-(-count // _STREAMS), max_batch)
        padded = np.zeros((-(-count // size) * size, *inputs.shape[1:]), dtype=np.float32)
        padded[:count] = inputs
        compiled = self._compiled_for((size, *inputs.shape[1:]), streams=_STREAMS)
        requests = [compiled.create_infer_request() for _ in range(min(_STREAMS, count))]
        outputs: list[list[np.ndarray]] = [[] for _ in compiled.outputs]
        for first in range(0, len(padded), size * _STREAMS):
            running = requests[: (len(padded) - first) // size]
            for k, request in enumerate(running):
                start = first + k * size
                request.start_async({0: padded[start : start + size]}, share_inputs=True)
            for request in running:
                request.wait()
                for i, parts in enumerate(outputs):
                    parts.append(np.array(request.get_output_tensor(i).data))
        return [np.concatenate(parts)[:count] for parts in outputs]

    def prepare_batches(self, item_shape: tuple[int, int, int], max_batch: int) -> None:
        """Compile now every request size :meth:`infer_batches` may use for inputs of
        ``item_shape`` ``(3, H, W)`` (a tenth to a quarter of a second each, which a live
        stream would otherwise spend on the frames where a new number of people first shows,
        dropping the frames behind them)."""
        sizes = range(1, max_batch + 1) if self.reshapeable else (self.input_shape[0],)
        for size in sizes:
            self._compiled_for((size, *item_shape), streams=_STREAMS)

    def _compiled_for(self, shape: tuple[int, ...], streams: int = 1):
        """The model compiled for input ``shape`` on ``streams`` CPU streams (1: latency
        mode, every thread on one request), once per process."""
        key = (shape, streams)
        with self._lock:
            compiled = self._compiled.get(key)
            if compiled is not None:
                self._compiled.move_to_end(key)
                return compiled
            model = self._model.clone()
            config: dict[str, str | int] = (
                {"PERFORMANCE_HINT": "LATENCY"}
                if streams == 1
                else {"PERFORMANCE_HINT": "THROUGHPUT", "NUM_STREAMS": streams}
            )
            if self.threads:
                config["INFERENCE_NUM_THREADS"] = self.threads
            try:
                if shape != self.input_shape:
                    model.reshape(list(shape))
                compiled = _core().compile_model(model, "CPU", config)
            except Exception as error:  # a job is told which model and size, not a C++ trace
                raise CnnModelError(
                    f"{self.path.name} does not compile on the CPU for input {shape} "
                    f"({_first_line(error)})"
                ) from None
            self._compiled[key] = compiled
            if len(self._compiled) > _MAX_SHAPES:
                self._compiled.popitem(last=False)
            return compiled


_CORE = None
_NETWORKS: dict[tuple[str, int, int, int], Network] = {}
_NETWORKS_LOCK = threading.Lock()


def _core():
    global _CORE
    if _CORE is None:
        import openvino  # imported on first use: the embedded detector never loads it

        _CORE = openvino.Core()
    return _CORE


def load_network(path: str | os.PathLike[str], threads: int = 0) -> Network:
    """The model at ``path``, read once per process (per file version and thread count).

    Raises
    ------
    CnnModelError
        A missing file, an IR without its ``.bin``, a file OpenVINO cannot read, or a model
        without one image input ``(N, 3, H, W)``.
    """
    path = Path(path)
    if path.suffix.lower() not in MODEL_SUFFIXES:
        raise CnnModelError(
            f"{path} is not a CNN model file: expected an OpenVINO IR .xml (with its .bin "
            "beside it) or an .onnx file"
        )
    try:
        stat = path.stat()
    except OSError as error:
        raise CnnModelError(f"cannot read the CNN model {path}: {error.strerror}") from None
    if path.suffix.lower() == ".xml" and not path.with_suffix(".bin").is_file():
        raise CnnModelError(f"{path} has no weights file {path.with_suffix('.bin').name} beside it")
    key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size, threads)
    with _NETWORKS_LOCK:
        if key not in _NETWORKS:
            _NETWORKS[key] = _read(path, threads)
        return _NETWORKS[key]


def _read(path: Path, threads: int) -> Network:
    try:
        model = _core().read_model(str(path))
    except Exception as error:  # OpenVINO raises RuntimeError subclasses with long C++ traces
        raise CnnModelError(
            f"{path} is not a model OpenVINO can read ({_first_line(error)})"
        ) from None
    if len(model.inputs) != 1 or not model.outputs:
        raise CnnModelError(
            f"{path.name} has {len(model.inputs)} inputs: the CNN detector runs models with one "
            "image input"
        )
    shape = model.inputs[0].get_partial_shape()
    if shape.rank.is_dynamic or shape.rank.get_length() != 4 or shape.is_dynamic:
        raise CnnModelError(f"{path.name}'s input is {shape}, not an image (N, 3, H, W)")
    n, c, h, w = (int(d.get_length()) for d in shape)
    input_shape = (n, c, h, w)
    if c != 3:
        raise CnnModelError(f"{path.name}'s input is {shape}, not a 3-channel image (N, 3, H, W)")
    outputs = tuple(
        tuple(d.get_length() if d.is_static else -1 for d in output.get_partial_shape())
        for output in model.outputs
    )
    # Whether the graph takes another size: its shapes re-inferred for one (a few ms; the
    # compile that follows a real size costs a tenth of a second or more, so it is not tried).
    try:
        model.clone().reshape([n, c, h + 32, w + 32])  # the one input
        reshapeable = True
    except Exception:
        reshapeable = False
    network = Network(path, threads, input_shape, outputs, reshapeable, _model=model)
    # Compile the model's own shape now, so that a file OpenVINO reads but cannot run fails
    # here, at load, and not on a job's first frame.
    network._compiled_for(input_shape)
    return network


def _first_line(error: Exception) -> str:
    """The first line of an OpenVINO error (they carry long C++ traces), at most 300 chars."""
    text = str(error).strip()
    return text.splitlines()[0][:300] if text else type(error).__name__

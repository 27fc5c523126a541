"""What the service's frame encodings cost: the annotated MP4 (H.264, the mp4v fallback), the
MCAP's and live cameras' H.264 access units, and JPEG.

    python benchmarks/video_encoding.py [--video PATH] [--frames N] [--heights H ...]
                                        [--repeats N] [--json]

Encodes the first ``frames`` frames of the video (default: 200 of the PETS09-S2L1 video of the
shared data) resized to each height (4:3, bilinear), one per 0.1 s, and reports milliseconds
per frame (best of ``repeats`` runs: encoding is deterministic, so the best is the least
disturbed) and kilobytes per frame:

* ``h264``, ``mp4v``: the annotated MP4's encoders (``service/outputs/video_out.py``), size of
  the file;
* ``h264-units``: :class:`~service.outputs.h264.AccessUnitEncoder` (x264 zerolatency, a key
  frame a second), as the MCAP stores frames and ``vtrack publish --h264`` sends them;
* ``jpeg``: ``encode_jpeg`` at quality 90, as ``vtrack publish`` sends frames by default.

x264 uses its default threads.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import cv2

# benchmarks/ first on sys.path would shadow the packages
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from service.outputs.h264 import AccessUnitEncoder
from service.outputs.video_out import H264Encoder, Mp4vEncoder
from service.streams.payloads import encode_jpeg

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import SHARED_DATA
    from _report import print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import print_json

DEFAULT_VIDEO = SHARED_DATA / "video" / "pets09_s2l1_480x360.avi"


def video_file(encoder_type, frames: list, path: Path) -> int:
    """Bytes of the MP4 ``encoder_type`` makes of the BGR ``frames``."""
    height, width = frames[0].shape[:2]
    encoder = encoder_type(path, width, height, 10.0)
    for index, frame in enumerate(frames):
        encoder.write(frame, index / 10)
    encoder.close()
    return path.stat().st_size


def access_units(frames: list, path: Path) -> int:
    """Bytes of the H.264 access units of the BGR ``frames`` (``path`` unused)."""
    height, width = frames[0].shape[:2]
    encoder = AccessUnitEncoder(width, height, "bgr24")
    units = [u for i, f in enumerate(frames) for _, u in encoder.encode(f, i * 10**8)]
    return sum(map(len, units + [u for _, u in encoder.flush()]))


def jpeg(frames: list, path: Path) -> int:
    """Bytes of the BGR ``frames`` as JPEG (``path`` unused)."""
    return sum(len(encode_jpeg(cv2.cvtColor(f, cv2.COLOR_BGR2RGB))) for f in frames)


ENCODERS = {
    "h264": lambda frames, path: video_file(H264Encoder, frames, path),
    "mp4v": lambda frames, path: video_file(Mp4vEncoder, frames, path),
    "h264-units": access_units,
    "jpeg": jpeg,
}


def read_frames(video: Path, count: int) -> list:
    capture = cv2.VideoCapture(str(video))
    frames = []
    while len(frames) < count and (frame := capture.read()[1]) is not None:
        frames.append(frame)
    capture.release()
    if not frames:
        raise SystemExit(f"no frames could be read from {video}")
    return frames


def measure(frames: list, height: int, repeats: int, folder: Path) -> dict[str, dict]:
    width = round(height * 4 / 3)
    sized = [cv2.resize(f, (width, height)) for f in frames]
    out = {}
    for name, encode in ENCODERS.items():
        path = folder / f"{name}_{height}.mp4"
        best = float("inf")
        for _ in range(repeats):
            start = time.perf_counter()
            size = encode(sized, path)
            best = min(best, time.perf_counter() - start)
        out[name] = {
            "ms_per_frame": 1000 * best / len(sized),
            "kb_per_frame": size / len(sized) / 1024,
        }
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--video", type=Path, default=DEFAULT_VIDEO)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--heights", type=int, nargs="+", default=[360, 576, 1080, 2160])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    frames = read_frames(args.video, args.frames)
    with tempfile.TemporaryDirectory(prefix="vtrack-encode-") as scratch:
        results = {f"{h}": measure(frames, h, args.repeats, Path(scratch)) for h in args.heights}
    if args.json:
        print_json({"frames": len(frames), "heights": results}, indent=2)
        return
    print(f"{len(frames)} frames; ms per frame / KB per frame")
    for height, row in results.items():
        cells = "  ".join(
            f"{n} {r['ms_per_frame']:.2f} / {r['kb_per_frame']:.1f}" for n, r in row.items()
        )
        print(f"{height:>5} px  {cells}")


if __name__ == "__main__":
    main()

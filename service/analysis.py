"""The pipeline run behind every job and ``vtrack analyze``: frames in, result files out.

:func:`analyze` drives one :class:`~tracking.pipeline.FramePipeline` over a video, hands every
tracked frame to the result writers as it is computed, and reports progress. The files are
written in a scratch folder; :func:`publish` moves them into place only once the run has
finished, so a partial result is never served as a complete one.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from api_schemas.analytics import AnalyticsCounts, AnalyticsResult
from api_schemas.jobs import JobOptions, OutputFormat
from api_schemas.tracks import VideoInfo
from service.analytics import FrameAnalytics
from service.convert import frame_message
from service.frames import (
    FrameSource,
    ReadProgress,
    is_greyscale,
    open_frames,
)
from service.outputs import RESULT_FILES, RunSummary, h264, open_writers
from service.outputs.base import ANALYTICS_FILE, StreamInfo
from service.pipelines import (
    JobPlan,
    OptionsError,
    PipelineResources,
    build_pipeline,
    check_options,
)
from tracking.correlation import PRESETS
from tracking.detection.base import Detections
from tracking.gap_filling import GapFiller
from tracking.people import PeopleTrackerConfig

log = logging.getLogger(__name__)

ProgressCallback = Callable[[int, int, float | None], bool]
"""Called with (frames read so far, frames tracked so far, frames tracked per second) at most
every ``progress_interval`` seconds; returning ``False`` stops the run."""


class AnalysisStopped(Exception):
    """The progress callback asked the run to stop (cancelled, or the job is no longer ours)."""


@dataclass(slots=True)
class AnalysisResult:
    """A finished run: its files (still in the scratch folder until published)."""

    files: dict[OutputFormat, Path]
    video: VideoInfo
    frames_processed: int
    seconds: float
    options: JobOptions
    """The options that ran: detector 'auto' resolved, the CNN's model named, tracker.pose and
    tracker.reid true or false with their models named."""
    warnings: list[str] = field(default_factory=list)
    analytics: AnalyticsCounts | None = None
    """The counts of the job's zones and lines (None: it watched none)."""
    analytics_file: Path | None = None
    """Their events and counts (:data:`ANALYTICS_FILE`, beside the result files)."""


# -- the run ---------------------------------------------------------------------------------


def analyze(
    video: str | os.PathLike[str] | FrameSource,
    job: JobOptions | JobPlan,
    scratch: Path,
    *,
    resources: PipelineResources | None = None,
    job_id: str | None = None,
    filename: str | None = None,
    progress: ProgressCallback | None = None,
    progress_interval: float = 0.5,
    detections: Callable[[int], Detections] | None = None,
) -> AnalysisResult:
    """Track ``video`` (a path, or frames opened already) and write the requested results into
    ``scratch`` (emptied first).

    ``job``: the job's options, checked here against ``resources`` and the video, or their
    plan checked already (:func:`~service.pipelines.check_options` with the same video), which
    runs as it is. ``detections``, for people, gives the detections of each frame from its
    index (public detections: :meth:`~tracking.detection.external.MotDetections.for_frame`);
    the options' detector then finds nobody.

    Raises
    ------
    FrameSourceError
        The video cannot be decoded.
    OptionsError
        Options that cannot run here.
    AnalysisStopped
        ``progress`` returned ``False``.
    ValueError
        The pipeline rejected a frame or the first box.
    """
    started = time.perf_counter()
    source = video if isinstance(video, FrameSource) else open_frames(Path(video))
    if isinstance(job, JobPlan):
        plan = job
    else:
        plan = check_options(
            job, resources or PipelineResources(), source, detect=detections is None
        )
    # the results name what ran: the pose and re-identification networks (true or false,
    # their models), and the detector ('auto' resolved, the CNN's model named) unless the
    # detections are handed in
    options = plan.options
    if detections is not None and options.mode != "people":
        raise OptionsError("detections are for tracking people, not a single target")
    pipeline = build_pipeline(plan)
    log.debug(
        "job %s: %dx%d video, %.3f frames per second, %s frames announced; options %s",
        job_id,
        source.width,
        source.height,
        source.timing_fps,
        source.frame_count,
        options.model_dump_json(exclude_defaults=True),
    )
    if scratch.exists():
        shutil.rmtree(scratch)
    scratch.mkdir(parents=True)
    info = StreamInfo(
        width=source.width,
        height=source.height,
        fps=source.timing_fps,
        frame_step=options.frame_step,
        part_names=tuple(pipeline.part_names),
        skeleton=tuple(pipeline.skeleton),
        mode=options.mode,
        options=options,
        job_id=job_id,
        filename=filename,
        mcap_images=options.mcap_images,
        pixel_aspect=source.pixel_aspect,
        analytics=plan.analytics,
    )
    writers = open_writers(list(options.formats), scratch, info)
    analytics = None if plan.analytics is None else FrameAnalytics(plan.analytics)
    filler = GapFiller(options.fill_gaps) if options.fill_gaps > 0 else None
    processed, read, last_report = 0, ReadProgress(), time.perf_counter()
    greyscale = False

    def report() -> None:  # after every frame read, those before options.start too
        nonlocal last_report
        now = time.perf_counter()
        if progress is None or now - last_report < progress_interval:
            return
        last_report = now
        log.debug("job %s: %d frames read, %d tracked", job_id, read.frames, processed)
        if not progress(read.frames, processed, processed / max(now - started, 1e-9)):
            raise AnalysisStopped(f"stopped after {read.frames} frames")

    read.on_read = report
    try:
        for frame in source.timed(options.frame_step, read, options.start, options.end):
            if processed == 0:
                greyscale = is_greyscale(frame.image)
            given = None if detections is None else detections(frame.index)
            tracks = pipeline.process(frame.image, frame.timestamp, given)
            if filler is not None:
                # numbered by video frame, as the messages are
                for filled in filler.push(dataclasses.replace(tracks, frame_index=frame.index)):
                    late = frame_message(filled)
                    for writer in writers.values():
                        writer.write_filled(late)
            message = frame_message(tracks, frame.index)
            events = [] if analytics is None else analytics.update(tracks, frame.index)
            for writer in writers.values():
                writer.write(frame, message, events)
            processed += 1
        if processed == 0:  # the video is shorter than it says, or the range has no frame
            raise OptionsError(
                f"no frame of the video lies between start {options.start:g} s and end "
                f"{options.end:g} s"
                if read.reached_end
                else f"no frame of the video is at or after start {options.start:g} s: its "
                f"last frame is at {read.end_time:.2f} s"
            )
        summary = _summary(source, options, read, processed, filename, greyscale)
        summary.warnings.extend(plan.warnings)
        if analytics is not None:
            summary.analytics = analytics.result()
            write_analytics(scratch / ANALYTICS_FILE, summary.analytics)
        for writer in writers.values():
            writer.close(summary)
    except BaseException:
        for writer in writers.values():
            writer.abort()
        raise
    seconds = time.perf_counter() - started
    assert summary.video is not None  # an upload's summary has its video
    return AnalysisResult(
        files={fmt: writer.path for fmt, writer in writers.items()},
        video=summary.video,
        frames_processed=processed,
        seconds=seconds,
        options=options,
        warnings=summary.warnings,
        analytics=None if summary.analytics is None else summary.analytics.counts,
        analytics_file=None if summary.analytics is None else scratch / ANALYTICS_FILE,
    )


def greyscale_warning(mode: str, preset: str | None) -> str | None:
    """What greyscale video takes from the colour cues of a job of ``mode`` (a single target
    tracked with ``preset``); None for a grey preset."""
    if mode == "people":
        return (
            "the video is greyscale (an infrared or monochrome camera?): every person's "
            "clothing colours are the same grey, so they do not help keep people apart or "
            "recognise those who come back; identities rest on motion and appearance alone"
        )
    config = None if preset is None else PRESETS.get(preset)
    colour = "+".join(config.colour_features) if config is not None else ""
    if not colour:
        return None
    return (
        f"the video is greyscale: the colour features ({colour}) of preset {preset} see "
        "no colour in it; a grey preset (rcsk_gray) follows the same intensities without them"
    )


def _summary(
    source: FrameSource,
    options: JobOptions,
    read: ReadProgress,
    processed: int,
    filename: str | None,
    greyscale: bool = False,
) -> RunSummary:
    warnings = []
    frames_read = read.frames
    if source.fps is None and source.path.is_dir():
        warnings.append(
            "the image folder states no frame rate (no seqinfo.ini frameRate): its frames are "
            f"stamped {source.timing_fps:g} per second; give its rate with --fps"
        )
    elif source.fps is None:
        warnings.append(
            "the video states no usable frame rate; frames without a presentation time of their "
            f"own are stamped {source.timing_fps:g} per second"
        )
    warnings.extend(source.notes)
    warnings.extend(damage_warnings(source, read))
    if greyscale and (lost := greyscale_warning(options.mode, options.preset)):
        warnings.append(lost)
    confirm_hits = options.tracker.confirm_hits or PeopleTrackerConfig().confirm_hits
    if options.mode == "people" and processed < confirm_hits:
        tracked = "1 frame was" if processed == 1 else f"{processed} frames were"
        warnings.append(
            f"only {tracked} tracked, and a person is reported once seen in {confirm_hits} "
            "(tracker.confirm_hits): for a clip this short, set tracker.confirm_hits to 1"
        )
    missing = h264.h264_unavailable()
    if missing is not None and OutputFormat.mp4 in options.formats:
        warnings.append(f"the annotated video is mp4v, which browsers do not play: {missing}")
    if (
        missing is not None
        and OutputFormat.mcap in options.formats
        and options.mcap_images == "h264"
    ):
        warnings.append(f"the mcap holds JPEG images instead of H.264 video: {missing}")
    video = VideoInfo(
        filename=filename,
        width=source.width,
        height=source.height,
        fps=source.fps,
        frames_announced=source.frame_count if source.count_stated else 0,
        frames_read=frames_read,
        frame_step=options.frame_step,
        start=options.start,
        end=options.end,
        pixel_aspect_ratio=source.pixel_aspect,
    )
    return RunSummary(video=video, frames_processed=processed, warnings=warnings)


def damage_warnings(source: FrameSource, read: ReadProgress) -> list[str]:
    """What to tell the user of frames the video lacks: damaged ones in its course, those at
    its start, before its first keyframe (a clip cut from a longer recording), and at its end,
    before what its container announces (a truncated or damaged file); ``[]`` when it lacks
    none.

    A stated frame count is a promise; where the container states none (Matroska, WebM),
    OpenCV's count is the duration times the rate, which a variable-rate video does not reach,
    so there the last frame's time is held against the duration, allowing two frame periods
    (the last frame lasts one; containers round).
    """
    warnings = []
    if lost := read.undecodable:
        shown = ", ".join(map(str, lost[:5])) + (
            f" and {len(lost) - 5} more" if len(lost) > 5 else ""
        )
        frames = f"frame {shown} was" if len(lost) == 1 else f"{len(lost)} frames ({shown}) were"
        warnings.append(
            f"{frames} damaged and did not decode (frame_index counting from 0): they have no "
            "tracks, and tracking went on with the frames after them"
        )
    if source.lead_frames:
        frames = "frame" if source.lead_frames == 1 else f"{source.lead_frames} frames"
        warnings.append(
            f"the first {frames} ({source.lead_seconds:.2f} s) could not be decoded: the video "
            "starts without a keyframe, as a clip cut from a longer recording does; tracking "
            "starts at its first keyframe, and frame numbers and times count from there"
        )
    if read.reached_end:  # reading stopped at the end asked for, before the video's
        return warnings
    if source.count_stated:
        decoded = source.lead_frames + read.frames
        if not (source.frame_count and decoded < source.frame_count):
            return warnings
        read_part = f"{decoded} of the {source.frame_count} frames"
    else:
        end_time = source.lead_seconds + read.end_time
        if not (source.duration and end_time + 2.0 / source.timing_fps < source.duration):
            return warnings
        read_part = f"{end_time:.2f} s of the {source.duration:.2f} s"
    warnings.append(
        f"the video ended after {read_part} its container announces (truncated or damaged "
        "file); the frames that decoded were tracked"
    )
    return warnings


def write_analytics(path: Path, result: AnalyticsResult) -> None:
    """The events and counts of a run's zones and lines, as ``analytics.json``."""
    path.write_text(result.model_dump_json(by_alias=True), encoding="utf-8")


def publish(result: AnalysisResult, folder: Path) -> dict[OutputFormat, Path]:
    """Move a finished run's files from its scratch folder into ``folder`` (atomic renames),
    the events of its zones and lines (:data:`ANALYTICS_FILE`) too.

    The folder then holds this run's results only: a result file of a format the run did not
    write, left there by an earlier run, is removed rather than passed off as this run's.
    """
    folder.mkdir(parents=True, exist_ok=True)
    published = {}
    for fmt, path in result.files.items():
        target = folder / path.name
        os.replace(path, target)
        published[fmt] = target
    for fmt, name in RESULT_FILES.items():
        if fmt not in published:
            (folder / name).unlink(missing_ok=True)
    if result.analytics_file is not None:
        os.replace(result.analytics_file, folder / ANALYTICS_FILE)
    else:
        (folder / ANALYTICS_FILE).unlink(missing_ok=True)
    return published

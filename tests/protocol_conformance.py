"""The protocols' implementations, checked by the type checker instead of ``isinstance`` tests.

mypy checks this module (``[tool.mypy] files`` in pyproject.toml; ``.ci/run`` runs it): each
function hands an implementation to where its protocol is expected, so a method renamed, a
parameter or return type changed, or an attribute dropped on either side fails the check. A
runtime ``isinstance`` against a protocol sees only that the names exist, not their signatures.
Nothing here runs: pytest collects no test from this module.
"""

from __future__ import annotations

from service.jobs.database import Database, PostgresDatabase, SqliteDatabase
from service.jobs.files import FolderFiles, JobFiles
from service.outputs.base import ResultWriter
from service.outputs.json_out import JsonWriter
from service.outputs.mcap_out import McapWriter
from service.outputs.mot_out import MotWriter
from service.outputs.video_out import VideoWriter
from tracking.correlation.learning import CorrelationFilter, KernelFilter, MosseFilter
from tracking.correlation.regularized import TemporalRegularizedFilter
from tracking.correlation.tracker import CorrelationTracker
from tracking.detection.base import Detector
from tracking.detection.cnn.detector import CnnDetector
from tracking.detection.dpm.detector import DpmDetector
from tracking.detection.external import MotDetections, SubmittedDetections
from tracking.detection.hog_people import HogPeopleDetector
from tracking.pipeline import FramePipeline, PeoplePipeline, SingleTargetPipeline
from tracking.types import Tracker

# Single-target trackers (thesis Part I) and their correlation filters.


def correlation_tracker(tracker: CorrelationTracker) -> Tracker:
    return tracker


def mosse_filter(learner: MosseFilter) -> CorrelationFilter:
    return learner


def kernel_filter(learner: KernelFilter) -> CorrelationFilter:
    return learner


def temporal_regularized_filter(learner: TemporalRegularizedFilter) -> CorrelationFilter:
    return learner


# Person detectors (thesis Part II), ours and those that read detections from outside.


def hog_people_detector(detector: HogPeopleDetector) -> Detector:
    return detector


def dpm_detector(detector: DpmDetector) -> Detector:
    return detector


def cnn_detector(detector: CnnDetector) -> Detector:
    return detector


def mot_detections(detector: MotDetections) -> Detector:
    return detector


def submitted_detections(detector: SubmittedDetections) -> Detector:
    return detector


# Frames in, tracks out.


def single_target_pipeline(pipeline: SingleTargetPipeline) -> FramePipeline:
    return pipeline


def people_pipeline(pipeline: PeoplePipeline) -> FramePipeline:
    return pipeline


# The service's result files and job storage.


def json_writer(writer: JsonWriter) -> ResultWriter:
    return writer


def mcap_writer(writer: McapWriter) -> ResultWriter:
    return writer


def mot_writer(writer: MotWriter) -> ResultWriter:
    return writer


def video_writer(writer: VideoWriter) -> ResultWriter:
    return writer


def folder_files(files: FolderFiles) -> JobFiles:
    return files


def sqlite_database(database: SqliteDatabase) -> Database:
    return database


def postgres_database(database: PostgresDatabase) -> Database:
    return database

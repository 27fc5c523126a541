"""Result writers: each turns the stream of tracked frames into one file, incrementally.

A writer receives every tracked frame as it is computed (``write``) and completes its file in
``close``; an interrupted run leaves only a partial file in the attempt's scratch folder, which
is never served (see :mod:`service.analysis`). A live camera's recording is the same MCAP writer
in stream mode (:attr:`~service.outputs.base.StreamInfo.live`, :mod:`service.streams.recording`);
``vtrack track`` writes its boxes with :class:`~service.outputs.box_rows.BoxRowWriter`.
"""

from service.outputs.base import RESULT_FILES, ResultWriter, RunSummary, open_writers

__all__ = ["RESULT_FILES", "ResultWriter", "RunSummary", "open_writers"]

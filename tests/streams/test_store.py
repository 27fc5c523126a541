"""The streams' table (service.streams.store): specs stored by earlier versions, track
id reservations."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from api_schemas.streams import (
    StreamSpec,
)
from service.streams.store import StreamStore


@pytest.mark.parametrize(
    "spec", [{"record_keep": 3}, {"record": False, "record_segment": 60}, {"record_images": "jpeg"}]
)
def test_recording_options_without_record_are_refused_but_stored_ones_still_read(tmp_path, spec):
    with pytest.raises(ValidationError, match="only with record: true"):
        StreamSpec.model_validate({"camera": "gate", **spec})
    # a stream an earlier version accepted with them still lists and starts
    store = StreamStore(tmp_path / "jobs.db")
    try:
        # written as an earlier version did (model_copy does not validate)
        store.put(StreamSpec(camera="gate").model_copy(update=spec))
        [record] = store.all()
        assert record.spec.camera == "gate" and not record.spec.record
    finally:
        store.close()
    assert StreamSpec.model_validate({"camera": "gate", **spec, "record": True}).record


def test_track_id_reservations_only_go_up_and_outlive_the_stream(tmp_path):
    store = StreamStore(tmp_path / "jobs.db")
    try:
        assert store.reserved_track_ids("gate") == 0  # never tracked: ids start at 1
        store.reserve_track_ids("gate", 100)
        store.reserve_track_ids("gate", 40)  # a late, lower write does not take ids back
        store.reserve_track_ids("hall", 7)
        spec = StreamSpec(camera="gate")
        store.put(spec)
        store.delete("gate")
    finally:
        store.close()
    reopened = StreamStore(tmp_path / "jobs.db")  # a worker's own connection, or the next run
    try:
        assert reopened.reserved_track_ids("gate") == 100
        assert reopened.reserved_track_ids("hall") == 7
    finally:
        reopened.close()

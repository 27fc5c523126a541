"""Capture times from a camera's presentation times: spaced as the camera took the frames,
whatever bursts the network and the stream study deliver them in."""

from __future__ import annotations

import numpy as np
import pytest

from service.streams.capture_clock import JUMP_SECONDS, SLEW, WINDOW_SECONDS, CaptureClock

PERIOD = 0.1  # a camera at 10 frames per second
DELAY = 0.05  # the network's least delay


def camera_run(
    frames: int, *, burst: int = 8, rate: float = 1.0, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Capture times (this machine's clock), positions (the camera's, from an arbitrary origin,
    its clock running ``rate`` times ours) and arrival times of a camera's frames: the first
    ``burst`` come at once (the stream study), the rest after the least delay plus up to 0.3 s
    of congestion, in order."""
    rng = np.random.default_rng(seed)
    captured = 1000.0 + PERIOD * np.arange(frames)
    positions = 7.5 + (captured - captured[0]) * rate
    arrivals = captured + DELAY + rng.uniform(0.0, 0.3, frames) * (rng.random(frames) < 0.3)
    arrivals[:burst] = arrivals[burst - 1]
    return captured, positions, np.maximum.accumulate(arrivals)


def stamps_of(clock: CaptureClock, positions, arrivals) -> np.ndarray:
    return np.array([clock.stamp(p, a) for p, a in zip(positions, arrivals, strict=True)])


def assert_camera_spacing(stamps: np.ndarray) -> None:
    """Spaced as the camera took them, within the clock's slew."""
    spacing = np.diff(stamps)
    assert np.all(spacing >= PERIOD * (1 - SLEW) - 1e-9)
    assert np.all(spacing <= PERIOD * (1 + SLEW) + 1e-9)


def test_frames_are_stamped_as_the_camera_spaced_them_not_as_they_arrived():
    captured, positions, arrivals = camera_run(600)
    stamps = stamps_of(CaptureClock(), positions, arrivals)
    # Arrival times would put the study's burst at one instant and congestion's in clumps.
    assert np.diff(arrivals).min() == 0.0 and np.abs(np.diff(arrivals) - PERIOD).max() > 0.2
    # Stamps keep the camera's spacing, within the clock's slew while it settles.
    assert_camera_spacing(stamps)
    # They start at the first frame's arrival (its delay unknown yet), ahead of the burst's
    # frames' true times, and settle on capture + the least delay, never after arrival.
    assert stamps[0] == pytest.approx(arrivals[0])
    settled = slice(150, None)  # 15 s in
    np.testing.assert_allclose(stamps[settled], captured[settled] + DELAY, atol=0.005)
    assert np.all(stamps[settled] <= arrivals[settled])


@pytest.mark.parametrize("rate", [1.001, 0.999])
def test_a_camera_clock_that_drifts_is_followed(rate):
    # 1000 ppm: an hour apart the clocks differ by 3.6 s
    captured, positions, arrivals = camera_run(36_000, rate=rate)
    stamps = stamps_of(CaptureClock(), positions, arrivals)
    assert np.all(np.diff(stamps) > 0)
    # The least delay of the last WINDOW_SECONDS is stale by up to the drift over that window.
    error = stamps[-6000:] - (captured[-6000:] + DELAY)
    assert error.max() < 0.005 and error.min() > -WINDOW_SECONDS * 1e-3 - 0.005


def test_a_new_connection_starts_again_from_its_first_frame_and_never_goes_back():
    clock = CaptureClock()
    _, positions, arrivals = camera_run(100, burst=1)
    first = stamps_of(clock, positions, arrivals)
    clock.restart()  # reconnected 2 s later: positions count from 0 again
    _, positions, later = camera_run(50, burst=20, seed=1)
    later = later - later[0] + arrivals[-1] + 2.0
    second = stamps_of(clock, positions - positions[0], later)
    assert second[0] == pytest.approx(later[0]) and later[0] > first[-1]
    assert_camera_spacing(second)


def test_a_break_in_the_camera_clock_starts_it_over_and_stamps_stay_in_order():
    index = np.arange(300)
    captured = 1000.0 + PERIOD * index
    positions = 7.5 + PERIOD * index
    positions[100:] -= 7.5 + PERIOD * 100  # the camera restarted: back to 0
    positions[200:] += 2 * JUMP_SECONDS  # its clock was set forward
    stamps = stamps_of(CaptureClock(), positions, captured + DELAY)
    np.testing.assert_allclose(stamps, captured + DELAY, atol=1e-9)


def test_a_stream_without_times_is_stamped_on_arrival_in_order():
    clock = CaptureClock()
    assert [clock.stamp(None, t) for t in (5.0, 5.2, 5.1, 5.3)] == [5.0, 5.2, 5.2, 5.3]


@pytest.mark.parametrize("rate", [2.5, 0.4])  # FFmpeg's made-up 25 fps, a camera's 10 or 62.5
def test_times_that_do_not_keep_pace_with_real_time_are_given_up_for_arrival_times(rate):
    _, positions, arrivals = camera_run(2000, burst=1, rate=rate)
    clock = CaptureClock()
    stamps = stamps_of(clock, positions, arrivals)
    assert not clock.trusted
    spacing = np.diff(stamps)
    assert np.all(spacing >= 0) and np.all(spacing[np.diff(arrivals) > 0] > 0)  # never frozen
    # stamps end up on the arrival times, spaced as the frames arrived
    np.testing.assert_allclose(stamps[-300:], arrivals[-300:], atol=1e-6)
    # and were never further than the drift allowed from them
    assert np.abs(stamps - arrivals).max() <= JUMP_SECONDS + PERIOD * rate
    clock.restart()  # a new connection is trusted again
    assert clock.trusted

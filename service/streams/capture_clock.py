"""When a network camera took its frames, on this machine's clock.

A frame's arrival time is a poor capture time: the stream study hands over a second of frames at
once when a connection opens, and a congested network delivers frames in bursts after a pause.
The tracker's motion model runs on the differences of these times, and a burst stamped on
arrival is a run of frames a few milliseconds apart that a person crossed in a tenth of a second
each. The camera's own presentation times are spaced as the frames were taken, but count from an
arbitrary origin on the camera's clock. :class:`CaptureClock` maps them onto this machine's
clock: ``capture = offset + position``, with the offset the smallest ``arrival - position`` seen
lately (the least-delayed frame: its delay is the network's floor, not a burst's). The offset
moves towards that estimate at a bounded rate, so stamps stay in order and their spacing stays
within :data:`SLEW` of the camera's. A frame without a presentation time (FFmpeg gives an RTSP
stream's first packet none) is stamped on arrival. A connection whose times drift
:data:`JUMP_SECONDS` away from real time a little at a time (FFmpeg makes up 25 frames a second
for a raw H.264 or MJPEG stream, whatever the camera's rate) is not on the camera's clock: its
frames are stamped on arrival from then on, the stamps moving to the arrival times at the same
bounded rate.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["JUMP_SECONDS", "SLEW", "WINDOW_SECONDS", "CaptureClock", "Captured"]

WINDOW_SECONDS = 30.0
"""The least delay is looked for over the frames that arrived in this many seconds: a lasting
change of route or load moves it within this time. A camera clock slower than ours by a
fraction ``r`` makes the delays grow, and stamps then run early by up to ``WINDOW_SECONDS r``
(0.03 s for a clock 1000 ppm off, 3.6 s an hour)."""

SLEW = 0.1
"""Largest correction of the offset per second of stream: stamps are spaced within 10% of the
camera's spacing while the offset settles (about 10 s after a second-long opening burst)."""

JUMP_SECONDS = 10.0
"""A frame whose time moved this much more (or less) than real time since the previous frame is
a break in the camera's clock (a restart, a wrap-around): the clock starts over from that frame.
Longer than the gateway's read timeout (5 s by default), after which a silent camera is
connected to again anyway. Stamps that drift this far from arrival times without such a break
are not on the camera's clock."""


@dataclass(frozen=True, slots=True)
class Captured:
    """A frame (or an H.264 access unit) and the time it was taken (Unix time, seconds)."""

    data: np.ndarray | bytes
    time: float


class CaptureClock:
    """Capture times of one camera's frames from their stream positions and arrival times.

    Stamps never go back, across :meth:`restart` (a new connection) included: the tracker takes
    a time that goes back for a camera that restarted and starts over.

    Attributes
    ----------
    trusted:
        Whether this connection's times are used; ``False`` once they drifted away from real
        time (its frames are then stamped on arrival).
    """

    def __init__(self) -> None:
        self._last: float | None = None
        self.restart()

    def restart(self) -> None:
        """Forget the stream's origin: the next frame comes from a new connection."""
        self._offset: float | None = None
        self._position = self._arrival = 0.0
        self._lags: deque[tuple[float, float]] = deque()  # (arrival, lag), lags increasing
        self.trusted = True

    def stamp(self, position: float | None, arrival: float) -> float:
        """The capture time of a frame at ``position`` seconds of the stream (``None``: the
        stream has no times) that arrived at ``arrival``."""
        if position is None:
            return self._in_order(arrival)
        # (an offset comes from a stamped frame: the last stamp is there too)
        if self._offset is not None and self._last is not None and self.trusted:
            drift = self._offset + position - arrival
            mismatch = (position - self._position) - (arrival - self._arrival)
            if abs(mismatch) > JUMP_SECONDS:
                self._offset = None  # a break: start over from this frame
            elif abs(drift) > JUMP_SECONDS:
                # not the camera's clock: go on from the last stamp (never back) on arrival times
                self.trusted = False
                self._offset = max(self._last - self._arrival, 0.0)
                self._position = arrival
                self._lags.clear()
        if not self.trusted:
            position = arrival
        lag = arrival - position
        if self._offset is None:
            self._lags.clear()  # lags from before a break are on another origin
        # the minimum over the window, kept as an increasing run (sliding-window minimum)
        while self._lags and self._lags[-1][1] >= lag:
            self._lags.pop()
        self._lags.append((arrival, lag))
        while self._lags[0][0] < arrival - WINDOW_SECONDS:
            self._lags.popleft()
        if self._offset is None:
            self._offset = lag
        else:
            step = SLEW * max(position - self._position, 0.0)
            self._offset += min(max(self._lags[0][1] - self._offset, -step), step)
        self._position, self._arrival = position, arrival
        return self._in_order(self._offset + position)

    def _in_order(self, time: float) -> float:
        if self._last is not None and time < self._last:
            time = self._last
        self._last = time
        return time

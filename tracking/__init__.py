"""Visual tracking after Danelljan (2013): the algorithms, with no HTTP and no Zenoh.

Import the subpackage you need (nothing is imported here, so ``import tracking`` stays cheap):

- :mod:`tracking.correlation`: single-target correlation trackers of thesis Part I
  (:class:`~tracking.correlation.CorrelationTracker`, its ``PRESETS``);
- :mod:`tracking.people`: every person in view with parts and occlusion, thesis Part II
  (:class:`~tracking.people.MultiPersonTracker`);
- :mod:`tracking.detection`: the ``Detector`` contract, the DPM engine, the embedded HOG
  default, detections from files or from the caller;
- :mod:`tracking.pipeline`: either tracker behind one ``process(frame, timestamp)``;
- :mod:`tracking.features`, :mod:`tracking.filtering`: colour features, Kalman and particle
  filters; :mod:`tracking.evaluation`: OTB sequences and the thesis's metrics;
- :mod:`tracking.types`: ``Box``, ``TrackerOutput`` and the frame and box checks.

Frames are RGB ``uint8`` ``(H, W, 3)`` arrays; boxes ``x, y, w, h`` in pixels from the
top-left corner, 0-based; times in seconds.
"""

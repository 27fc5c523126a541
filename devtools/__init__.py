"""Developer tools and test support, kept out of the installed packages.

``pip install .`` ships ``tracking``, ``service`` and ``api_schemas`` only
(``[tool.setuptools.packages.find]`` in ``pyproject.toml``); this folder is used from a checkout,
run from the repository root:

- :mod:`devtools.calibrate`: fits a detector's score calibration on MOTChallenge ground truth
  (``python -m devtools.calibrate``);
- :mod:`devtools.cascade_fit`: fits the DPM star cascade's thresholds on OTB people
  (``python -m devtools.cascade_fit``);
- :mod:`devtools.testing`: a real ``vtrack serve`` in a subprocess (:class:`~devtools.testing.
  Server`) and waiting helpers, for the tests and the benchmarks;
- :mod:`devtools.simulated_cameras`: RTSP, MPEG-TS and HTTP cameras on loopback, for the stream
  tests and ``benchmarks/gateway.py``.
"""

"""Readers of the benchmark datasets' files, below both the detectors and the evaluation.

- :mod:`tracking.datasets.mot`: MOTChallenge folders (``seqinfo.ini``, ``gt.txt``, ``det.txt``),
  the one reader of their rows and the move between their 1-based pixels and the project's
  0-based boxes;
- :mod:`tracking.datasets.otb`: OTB sequences (frames, ground-truth boxes), the single-target
  benchmark's (thesis §5.1).

The package imports neither :mod:`tracking.detection` nor :mod:`tracking.evaluation`: the
detectors read public detections with it and the evaluation reads ground truth with it, so
neither needs the other (``tests/test_layers.py``). Nothing is re-exported here; import the
module.
"""

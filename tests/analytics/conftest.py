"""Fixtures of the analytics tests: the service tests' videos."""

from tests.service.conftest import long_video, pets_cut  # noqa: F401 (fixtures)

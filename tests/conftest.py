"""Test-wide settings. In CI (``CI`` set, as .ci/run's environment has it) hypothesis draws the same
examples every run, so a submission is judged on a fixed set; locally it draws new ones each run and
keeps failures in .hypothesis/, which is how it finds new hostile inputs."""

from __future__ import annotations

import os

from hypothesis import settings

# The validation fixture and --validation-report (tests/validation_report.py; docs/validation.md), and pytester,
# with which tests/test_validation_report.py runs the plugin on a small test file.
pytest_plugins = ["validation_report", "pytester"]

settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

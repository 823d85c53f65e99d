"""pytest plugin: ``--device FAMILY[:ADDRESS]`` opts real hardware into the contract tests.

Families: ``camera-opencv[:INDEX]``, ``camera-pylon[:SERIAL]`` (see tests/contracts.py,
``device_option``). Without the option, hardware test classes skip with a reason.
"""

from __future__ import annotations

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--device",
        action="append",
        default=[],
        metavar="FAMILY[:ADDRESS]",
        help="run the contract tests against real hardware too, e.g. --device camera-opencv:0 "
        "or --device camera-pylon:40012345 (repeatable)",
    )

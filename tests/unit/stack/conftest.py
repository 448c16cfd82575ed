"""Fixtures the stack's unit tests share."""

from __future__ import annotations

import pytest

from addt_dsl.stack.bridge_server import Limits, start_in_thread


@pytest.fixture(scope="module")
def server():
    """The reference bridge server on a free loopback port, for one test module."""
    srv = start_in_thread("127.0.0.1:0", Limits(idle_timeout_s=5.0))
    yield srv
    srv.shutdown()
    srv.server_close()

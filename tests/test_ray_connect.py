"""A Ray cluster address where nothing listens is refused at once in one line (ray.init retries for minutes)."""

from __future__ import annotations

import socket

import pytest

import rtloop
from rtloop.batch.on_ray import run_ray


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]  # closed again on return: nothing listens there


@pytest.mark.parametrize("scheme", ["", "ray://"])
def test_an_address_where_nothing_listens_is_refused_in_one_line(scheme):
    pytest.importorskip("ray")
    address = f"{scheme}127.0.0.1:{_closed_port()}"
    with pytest.raises(rtloop.RtloopError, match=r"ray: cannot connect to the cluster at .*127\.0\.0\.1") as info:
        list(run_ray([], address=address, threads=1, max_retries=0))
    assert "\n" not in str(info.value)

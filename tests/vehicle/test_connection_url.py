"""Connection strings are checked before any work that ends in opening them."""

from __future__ import annotations

import pytest

from urpt_gcs.errors import LinkError
from urpt_gcs.vehicle.protocol import DEFAULT_URL, check_url


@pytest.mark.parametrize(
    "url",
    [
        DEFAULT_URL,
        "udpout://192.168.1.20:14550",
        "tcpout://127.0.0.1:5760",
        "tcpin://0.0.0.0:5760",
        "udp://:14540",
        "serial:///dev/ttyACM0:57600",
        "serial_flowcontrol:///dev/ttyUSB0:921600",
        "serial:///dev/ttyACM0",
    ],
)
def test_strings_mavsdk_opens_are_accepted(url: str) -> None:
    check_url(url)


@pytest.mark.parametrize(
    ("url", "problem"),
    [
        ("foo://bad", "unknown kind of link"),
        ("127.0.0.1:14550", "unknown kind of link"),
        ("udpin://0.0.0.0", "port from 1 to 65535"),
        ("tcpout://127.0.0.1:0", "port from 1 to 65535"),
        ("udpin://0.0.0.0:x", "port from 1 to 65535"),
        ("serial://ttyACM0:57600", "device path"),
        ("serial:///dev/ttyACM0:fast", "device path"),
    ],
)
def test_other_strings_are_refused_in_one_line_with_examples(url: str, problem: str) -> None:
    with pytest.raises(LinkError) as caught:
        check_url(url)
    message = str(caught.value)
    assert f"--connect {url!r}" in message
    assert problem in message
    assert "udpin://0.0.0.0:14550" in message
    assert "\n" not in message

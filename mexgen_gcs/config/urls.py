"""Parsing of the `udp://HOST:PORT` addresses used by the radio receiver (no frames here).

Kept in the config layer so that mission validation and the io layer share one parser.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass

_HOSTNAME = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?"
                       r"(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*$")


@dataclass(frozen=True, slots=True)
class UdpAddress:
    """A UDP bind or send address. `host` is an IP literal (no brackets) or a host name."""

    host: str
    port: int

    def url(self) -> str:
        """Back to `udp://HOST:PORT` (IPv6 literals in brackets)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"udp://{host}:{self.port}"


def parse_udp_url(url: str) -> UdpAddress:
    """Parse `udp://HOST:PORT` (`udp://[::1]:14600` for IPv6). Port 0 means "any free port".

    Raises ValueError with a message saying what is expected.
    """
    expected = "expected udp://HOST:PORT, e.g. udp://0.0.0.0:14600"
    if not isinstance(url, str):
        raise ValueError(f"{expected}; found {url!r}")
    if not url.startswith("udp://"):
        raise ValueError(f"{expected}; {url!r} does not start with udp://")
    rest = url[len("udp://"):]
    if rest.startswith("["):
        close = rest.find("]")
        if close < 0 or not rest[close + 1:].startswith(":"):
            raise ValueError(f"{expected}; bad IPv6 address in {url!r}")
        host, port_text = rest[1:close], rest[close + 2:]
        try:
            ipaddress.IPv6Address(host)
        except ValueError as exc:
            raise ValueError(f"{expected}; {host!r} is not an IPv6 address") from exc
    else:
        host, sep, port_text = rest.rpartition(":")
        if not sep or not host:
            raise ValueError(f"{expected}; {url!r} has no host or no port")
        if ":" in host:
            raise ValueError(f"{expected}; write IPv6 addresses in brackets: udp://[{host}]:PORT")
        if not _is_ipv4(host) and not _HOSTNAME.match(host):
            raise ValueError(f"{expected}; {host!r} is not an IP address or host name")
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise ValueError(f"{expected}; port {port_text!r} is not a number in 0..65535")
    return UdpAddress(host, int(port_text))


def _is_ipv4(host: str) -> bool:
    try:
        ipaddress.IPv4Address(host)
    except ValueError:
        return False
    return True

"""Source URLs of `mexgen-gcs receive --source`:

- ``rtltcp://HOST:PORT``: an rtl_tcp server (default port 1234);
- ``rtlsdr://INDEX``: an RTL-SDR on USB through pyrtlsdr (the ``rtlsdr`` extra);
- ``soapy://ARGS``: a SoapySDR device, e.g. ``soapy://driver=airspy``;
- ``file:NAME.sigmf-meta`` (or ``.sigmf-data``): a SigMF recording;
- ``file:NAME.cu8?rate=2.4e6&centre=150.1e6``: raw samples (cu8, cs16 or cf32, from the
  extension or ``fmt=``) with the rate and centre frequency, Hz.
"""

from __future__ import annotations

from urllib.parse import parse_qs

from mexgen_gcs.receiver.sources import IQSource, SourceError, open_raw, open_sigmf

EXAMPLES = ("rtltcp://127.0.0.1:1234", "rtlsdr://0", "soapy://driver=airspy",
            "file:rec.sigmf-meta", "file:x.cu8?rate=2.4e6&centre=150.1e6")


def check_url(url: str) -> None:
    """Refuse a source URL of no known kind, before anything is started (SourceError)."""
    if not url.startswith(("rtltcp://", "rtlsdr://", "soapy://", "file:")):
        raise SourceError(f"source {url!r}: unknown kind; expected one of " + ", ".join(EXAMPLES))


def open_source(url: str) -> IQSource:
    """Open the source a URL names; SourceError says what is wrong and what is expected."""
    check_url(url)
    expected = "expected one of " + ", ".join(EXAMPLES)
    if url.startswith("rtltcp://"):
        from mexgen_gcs.receiver.rtltcp import RtlTcpSource

        host, sep, port = url[len("rtltcp://"):].rpartition(":")
        if not sep:
            host, port = url[len("rtltcp://"):], "1234"
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise SourceError(f"source {url!r}: {expected}")
        return RtlTcpSource(host, int(port))
    if url.startswith("rtlsdr://"):
        from mexgen_gcs.receiver.hardware import PyRtlSdrSource

        index = url[len("rtlsdr://"):] or "0"
        if not index.isdigit():
            raise SourceError(f"source {url!r}: the device index must be a number; {expected}")
        return PyRtlSdrSource(int(index))
    if url.startswith("soapy://"):
        from mexgen_gcs.receiver.hardware import SoapySource

        return SoapySource(url[len("soapy://"):])
    if url.startswith("file:"):
        path, _, query = url[len("file:"):].partition("?")
        if path.endswith((".sigmf-meta", ".sigmf-data")):
            return open_sigmf(path)
        params = {k: v[-1] for k, v in parse_qs(query).items()}
        fmt = params.get("fmt") or path.rpartition(".")[2]
        try:
            rate = float(params["rate"])
            centre = float(params.get("centre") or params["center"])
        except (KeyError, ValueError):
            raise SourceError(f"source {url!r}: a raw file needs ?rate=HZ&centre=HZ (numbers), "
                              "e.g. file:x.cu8?rate=2.4e6&centre=150.1e6") from None
        return open_raw(path, fmt, rate, centre)
    raise SourceError(f"source {url!r}: unknown kind; {expected}")

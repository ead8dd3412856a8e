"""IQ sources behind one interface, and file replay (SigMF recordings, raw cu8/cs16/cf32).

A source is configured once (``tune``) and then read in blocks. ``read`` blocks until samples
are there and returns an `IQBlock` (None at the end of a file or a closed stream). Sample
times come from the receiver's counter, not from the source; a live source says so
(``live``), and its blocks may report samples the source knows it lost (``lost_before``).
A recording fixes its own rate and centre (``fixed``).

A damaged recording (data shorter than its metadata says, a partial last sample, a float
sample that is not finite) is read up to the damage; ``damage`` then says where and why.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.errors import MexgenError
from mexgen_gcs.receiver.convert import SAMPLE_BYTES, SIGMF_TYPES, convert


class SourceError(MexgenError):
    """The source cannot be opened or configured (message names it and what is wrong)."""


@dataclass(frozen=True, slots=True)
class IQBlock:
    samples: NDArray[np.complex64]
    clipped: NDArray[np.bool_]
    raw: bytes
    """The bytes as the source delivered them (for recording), in ``fmt``."""
    fmt: str
    lost_before: int = 0


@dataclass(frozen=True, slots=True)
class Tuning:
    centre_hz: float
    rate_hz: float
    gain_db: float
    ppm: float


class IQSource(Protocol):
    @property
    def name(self) -> str: ...

    @property
    def live(self) -> bool: ...

    @property
    def fixed(self) -> Tuning | None:
        """Rate and centre the source imposes (a recording), else None."""

    @property
    def sets_ppm(self) -> bool:
        """The device applies the ppm correction itself."""

    @property
    def gain_table(self) -> tuple[int, ...] | None: ...

    def tune(self, tuning: Tuning) -> None: ...

    def read(self, max_samples: int) -> IQBlock | None: ...

    def close(self) -> None: ...


@dataclass
class FileSource:
    """Replay of a SigMF recording or a raw file (cu8/cs16/cf32 with rate and centre given)."""

    path: Path
    fmt: str
    rate_hz: float
    centre_hz: float
    meta: dict[str, Any] = field(default_factory=dict)
    expected_samples: int | None = None
    name: str = ""
    live: bool = False
    sets_ppm: bool = False
    gain_table: tuple[int, ...] | None = None
    damage: str | None = None
    gaps: list[tuple[int, int]] = field(default_factory=list)
    """(file sample, samples lost before it): captures whose ``core:global_index`` jumps."""
    _fh: Any = None
    _read: int = 0

    def __post_init__(self) -> None:
        self.name = self.name or f"file:{self.path}"
        try:
            self._fh = open(self.path, "rb")  # noqa: SIM115 - closed by close()
        except OSError as exc:
            raise SourceError(f"{self.path}: cannot read the samples: {exc.strerror}") from None

    @property
    def fixed(self) -> Tuning:
        return Tuning(self.centre_hz, self.rate_hz, float(self.meta.get("mexgen:gain_db", 0.0)),
                      0.0)

    @property
    def start_unix(self) -> float | None:
        value = self.meta.get("mexgen:start_unix")
        return float(value) if isinstance(value, int | float) else None

    def tune(self, tuning: Tuning) -> None:
        pass  # a recording is what it is; the plan was made for its band

    def read(self, max_samples: int) -> IQBlock | None:
        if self.damage is not None and self._fh is None:
            return None
        size = SAMPLE_BYTES[self.fmt]
        lost = 0
        upcoming = [g for g in self.gaps if g[0] >= self._read]
        if upcoming and upcoming[0][0] == self._read:
            lost = upcoming[0][1]
            upcoming = upcoming[1:]
        if upcoming:  # stop at the next gap
            max_samples = min(max_samples, upcoming[0][0] - self._read)
        raw = self._fh.read(max_samples * size)
        if not raw:
            self._check_end()
            return None
        if len(raw) % size:
            whole = self._read + len(raw) // size
            self.damage = (f"{self.path}: ends inside a sample after {whole} samples (a "
                           "truncated recording); read up to there")
            raw = raw[: len(raw) - len(raw) % size]
            self._fh.close()
            self._fh = None
        samples, clipped = convert(raw, self.fmt)
        if self.fmt == "cf32":
            bad = ~np.isfinite(samples.view(np.float32)).reshape(-1, 2).all(axis=1)
            if bad.any():
                k = int(np.argmax(bad))
                self.damage = (f"{self.path}: sample {self._read + k} is not a finite number "
                               f"(a damaged recording); read up to there")
                samples, clipped, raw = samples[:k], clipped[:k], raw[: k * size]
                if self._fh is not None:
                    self._fh.close()
                    self._fh = None
        self._read += samples.size
        if samples.size == 0:
            return None
        return IQBlock(samples, clipped, raw, self.fmt, lost_before=lost)

    def _check_end(self) -> None:
        if self.expected_samples is not None and self._read < self.expected_samples \
                and self.damage is None:
            self.damage = (f"{self.path}: {self._read} samples, the metadata says "
                           f"{self.expected_samples} (a truncated recording); read up to there")

    @property
    def samples_read(self) -> int:
        return self._read

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def open_raw(path: str | os.PathLike[str], fmt: str, rate_hz: float,
             centre_hz: float) -> FileSource:
    if fmt not in SAMPLE_BYTES:
        raise SourceError(f"{path}: unknown sample format {fmt!r}; expected cu8, cs16 or cf32")
    if not (math.isfinite(rate_hz) and rate_hz > 0 and math.isfinite(centre_hz)
            and centre_hz > 0):
        raise SourceError(f"{path}: a raw file needs rate > 0 and centre > 0 (Hz), "
                          f"e.g. file:x.cu8?rate=2.4e6&centre=150.1e6")
    return FileSource(Path(path), fmt, rate_hz, centre_hz)


def open_sigmf(path: str | os.PathLike[str]) -> FileSource:
    """A SigMF recording from its .sigmf-meta (or .sigmf-data) path."""
    p = Path(path)
    base = p.with_suffix("") if p.suffix in (".sigmf-meta", ".sigmf-data") else p
    meta_path, data_path = base.with_suffix(".sigmf-meta"), base.with_suffix(".sigmf-data")
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SourceError(f"{meta_path}: cannot read the SigMF metadata: {exc.strerror}") from None
    except ValueError as exc:
        raise SourceError(f"{meta_path}: not JSON ({exc}); expected SigMF metadata") from None
    glob = meta.get("global") if isinstance(meta, dict) else None
    if not isinstance(glob, dict):
        raise SourceError(f"{meta_path}: no 'global' object; expected SigMF metadata")
    dtype = glob.get("core:datatype")
    fmts = {v: k for k, v in SIGMF_TYPES.items()}
    if dtype not in fmts:
        raise SourceError(f"{meta_path}: core:datatype {dtype!r} is not supported; expected "
                          f"one of {sorted(fmts)}")
    rate = glob.get("core:sample_rate")
    captures = meta.get("captures") or [{}]
    centre = captures[0].get("core:frequency") if isinstance(captures[0], dict) else None
    if not isinstance(rate, int | float) or not isinstance(centre, int | float):
        raise SourceError(f"{meta_path}: needs global core:sample_rate and the first capture's "
                          "core:frequency (numbers, Hz)")
    count = glob.get("mexgen:sample_count")
    gaps = []
    lost_so_far = 0
    for cap in captures[1:]:
        start, index = cap.get("core:sample_start"), cap.get("core:global_index")
        if isinstance(start, int) and isinstance(index, int) and index - start > lost_so_far:
            gaps.append((start, index - start - lost_so_far))
            lost_so_far = index - start
    src = FileSource(data_path, fmts[dtype], float(rate), float(centre), meta=glob,
                     expected_samples=int(count) if isinstance(count, int) else None,
                     name=f"file:{meta_path}", gaps=gaps)
    return src

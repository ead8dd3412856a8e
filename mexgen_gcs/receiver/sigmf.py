"""SigMF recordings: the samples as the source delivered them, and the pulses as annotations.

``NAME.sigmf-data`` holds the raw samples (cu8 from an RTL-SDR, ci16_le or cf32_le); the
``NAME.sigmf-meta`` JSON (SigMF 1.x core namespace) gives the datatype, rate, centre and start
time, and one annotation per detected pulse (``core:sample_start``/``core:sample_count`` on
the recording's samples, ``core:freq_lower_edge``/``core:freq_upper_edge`` of the
tag's channel, ``core:label`` the tag id, and the calibrated power, SNR and noise floor in the
``mexgen:`` namespace). The metadata is rewritten atomically every ``flush_s`` seconds of
samples and at the end, so a recording cut short by a crash still opens and replays up to its
last sample. Samples the source lost start a new capture whose ``core:global_index`` is the
stream's counter there. ``mexgen:start_unix`` is the anchor of the sample clock, so a replay
times every pulse exactly as the live run did.
"""

from __future__ import annotations

import json
import os
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from mexgen_gcs.receiver.convert import SAMPLE_BYTES, SIGMF_TYPES
from mexgen_gcs.receiver.pipeline import Pulse
from mexgen_gcs.receiver.tuning import TuningPlan

SIGMF_VERSION = "1.0.0"


def base_of(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    return p.with_suffix("") if p.suffix in (".sigmf-meta", ".sigmf-data") else p


class SigmfWriter:
    def __init__(self, path: str | os.PathLike[str], fmt: str, plan: TuningPlan, *,
                 gain_db: float, cal_offset_db: float, description: str = "",
                 flush_s: float = 5.0) -> None:
        base = base_of(path)
        self.data_path = base.with_suffix(".sigmf-data")
        self.meta_path = base.with_suffix(".sigmf-meta")
        self.fmt = fmt
        self.plan = plan
        self._fh = open(self.data_path, "wb")  # noqa: SIM115 - closed by close()
        self._samples = 0
        self._flush_every = max(1, round(flush_s * plan.rate_hz))
        self._next_flush = self._flush_every
        self._annotations: list[dict[str, Any]] = []
        self._global: dict[str, Any] = {
            "core:datatype": SIGMF_TYPES[fmt], "core:sample_rate": plan.rate_hz,
            "core:version": SIGMF_VERSION, "core:recorder": "mexgen-gcs receive",
            "core:description": description or "VHF tag pulses",
            "mexgen:gain_db": gain_db, "mexgen:cal_offset_db": cal_offset_db,
            "mexgen:channel_width_hz": plan.channel_width_hz, "mexgen:ppm": plan.ppm,
            "mexgen:tags": [{"id": c.id, "freq_hz": c.freq_hz} for c in plan.channels],
        }
        self._start_unix: float | None = None
        self._captures: list[tuple[int, int]] = [(0, 0)]  # (file sample, stream sample)

    def gap(self, stream_sample: int) -> None:
        """Samples were lost: the next sample written is ``stream_sample`` of the stream (a
        new capture with ``core:global_index``, so a replay keeps the stream's counter)."""
        self._captures.append((self._samples, stream_sample))

    def _file_index(self, stream_sample: float) -> float:
        start, glob = next((c for c in reversed(self._captures) if c[1] <= stream_sample),
                           self._captures[0])
        return stream_sample - glob + start

    def write(self, raw: bytes, fmt: str, start_unix: float | None) -> None:
        """Append raw samples (in the recording's format); ``start_unix`` anchors sample 0."""
        if fmt != self.fmt:
            raise ValueError(f"recording is {self.fmt}, block is {fmt}")
        if self._start_unix is None and start_unix is not None:
            self._start_unix = start_unix
        self._fh.write(raw)
        self._samples += len(raw) // SAMPLE_BYTES[self.fmt]
        if self._samples >= self._next_flush:
            self._fh.flush()
            self.write_meta()
            self._next_flush = self._samples + self._flush_every

    def annotate(self, p: Pulse) -> None:
        ch = next(c for c in self.plan.channels if c.id == p.tag)
        half = self.plan.channel_width_hz / 2.0
        width = max(1, round(p.width_s * self.plan.rate_hz)) if p.width_s else 1
        self._annotations.append({
            "core:sample_start": max(0, round(self._file_index(p.sample))),
            "core:sample_count": width,
            "core:freq_lower_edge": ch.freq_hz - half, "core:freq_upper_edge": ch.freq_hz + half,
            "core:label": p.tag, "mexgen:t_unix": p.t_unix, "mexgen:rssi_dbm": p.rssi_dbm,
            "mexgen:snr_db": p.snr_db, "mexgen:noise_dbm": p.noise_dbm,
            "mexgen:clipped": p.clipped})

    def write_meta(self) -> None:
        glob = dict(self._global, **{"mexgen:sample_count": self._samples})
        captures: list[dict[str, Any]] = [
            {"core:sample_start": start, "core:global_index": glob_index,
             "core:frequency": self.plan.centre_hz} for start, glob_index in self._captures]
        if self._start_unix is not None:
            glob["mexgen:start_unix"] = self._start_unix
            captures[0]["core:datetime"] = datetime.fromtimestamp(
                self._start_unix, UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
        meta = {"global": glob, "captures": captures,
                "annotations": sorted(self._annotations, key=lambda a: a["core:sample_start"])}
        tmp = self.meta_path.with_suffix(".sigmf-meta.tmp")
        tmp.write_text(json.dumps(meta, indent=1), encoding="utf-8")
        os.replace(tmp, self.meta_path)

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()
            self.write_meta()

"""Corrections of measured records for known sensor faults (``data.corrections``).

A lateral accelerometer tilted by α about the longitudinal axis reads
x = cos α a_lat + sin α a_vert (docs/diagnose.md, "Sensor tilt from the
coupling"). With the vertical channel v = a_vert of the same point, the
rotation back is a_lat = (x - sin α v) / cos α. Correcting the record rather
than adding the tilt to the simulator keeps the reference date's noise model
valid for the channel: that model is a per-channel error in dB of the
*untilted* sensor, and a tilt mixes two channels whose model errors differ
(on the independent train, suspid's bogie lateral is 10 dB below the
vehicle's at 25-40 Hz while its vertical is right, so a simulated tilt adds
1-2.5 dB that the measurements do not have).

With calibration gains g_lat and g_vert on the two channels the measured
coupling is β = sin α g_lat / g_vert; the rotation with sin α = β removes it
exactly whatever the gains, which is why the correction takes the angle
asin β that ``suspid diagnose`` reports.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable, Sequence

import numpy as np

from suspid.errors import DataError
from suspid.interfaces import Response


def vertical_partner(channel: str, channels: Sequence[str]) -> str | None:
    """The vertical channel at the same point as lateral ``channel`` (its name with ``vertical``), or None."""
    if "lateral" not in channel:
        return None
    other = channel.replace("lateral", "vertical")
    return other if other in channels else None


def resolve(corrections: Sequence, channels: Sequence[str], *,
            error: Callable[[str, str], Exception] = lambda message, key: DataError(f"{key}: {message}")
            ) -> list[tuple[int, int, float]]:
    """Each correction as ``(row of the lateral channel, row of its vertical, tilt in rad)``; what ``suspid
    validate`` checks before anything is simulated.

    :param corrections: items with ``channel``, ``tilt_deg`` and ``vertical`` (None: the partner by name).
    :param channels: the channel order of the records' ``accelerations`` rows.
    :param error: makes the exception for a bad item from a message and its key (``data.corrections.<i>...``).
    :raises: ``error(...)`` for a channel that is not in the records or has no vertical partner.
    """
    names = list(channels)
    rows = []
    for i, c in enumerate(corrections):
        vertical = c.vertical or vertical_partner(c.channel, names)
        if c.channel not in names:
            raise error(f"'{c.channel}' is not a channel of the records ({', '.join(names)})",
                        f"data.corrections.{i}.channel")
        if vertical is None or vertical not in names:
            raise error(f"channel '{c.channel}' needs the vertical channel at its point (give 'vertical:'; "
                        f"channels: {', '.join(names)})", f"data.corrections.{i}.vertical")
        rows.append((names.index(c.channel), names.index(vertical), math.radians(c.tilt_deg)))
    return rows


def untilt(records: Sequence[Response], corrections: Sequence, channels: Sequence[str], *,
           error: Callable[[str, str], Exception] = lambda message, key: DataError(f"{key}: {message}")
           ) -> list[Response]:
    """``records`` with each listed lateral channel rotated back by its tilt (arguments as :func:`resolve`)."""
    rows = resolve(corrections, channels, error=error)
    if not rows:
        return list(records)
    out = []
    for r in records:
        acc = np.array(r.accelerations, dtype=float, copy=True)
        for k, kv, a in rows:
            acc[k] = (acc[k] - math.sin(a) * r.accelerations[kv]) / math.cos(a)
        out.append(dataclasses.replace(r, accelerations=acc))
    return out

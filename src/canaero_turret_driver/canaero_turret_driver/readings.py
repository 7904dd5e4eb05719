"""The turret's sensor readings (no ROS): base GNSS fix, headings, inclination, UTC and
zoom from the client's broadcast cache, each handed out once per arrival. A part of
:class:`~.device.TurretDevice` (its ``readings`` attribute), handed the client, apart so
the adapter's core reads in one sitting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .client import Sample, TurretClient
from .protocol.identifiers import BY_KEY


def si(sample: Sample | None) -> float | None:
    """The one conversion of an incoming value to SI (the device's own direction): the
    ICD unit of its identifier (deg -> rad, deg/s -> rad/s, ...); None for no sample or a
    value that is not a number (a status byte, a flag)."""
    if sample is None:
        return None
    value = sample.value
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return BY_KEY[sample.key].to_si(value)


def si_magnitude(sample: Sample | None) -> float | None:
    """:func:`si` without its sign (an accuracy sent signed), None as :func:`si`."""
    value = si(sample)
    return None if value is None else abs(value)


@dataclass(frozen=True)
class GnssFix:
    """One base-GNSS position (7.2): degrees, metres; `fresh` False once it went stale."""

    stamp: float
    latitude: float
    longitude: float
    altitude: float
    accuracy: float | None  # m (1 sigma), None when the node sent none
    fresh: bool


@dataclass(frozen=True)
class Heading:
    """A compass heading (rad, clockwise from north) and its accuracy (rad) if known."""

    stamp: float
    heading: float
    accuracy: float | None


@dataclass(frozen=True)
class Inclination:
    """The turret base's roll and pitch (rad)."""

    stamp: float
    roll: float
    pitch: float


class TurretReadings:
    """The sensor readings of :class:`~.device.TurretDevice`."""

    def __init__(self, client: TurretClient) -> None:
        self.client = client
        self._published: dict[str, float] = {}  # reading -> arrival of the last handed out

    def fresh(self, key: str) -> Sample | None:
        """The latest `key` sample if it is numeric and not stale, else None (the device's
        capabilities read their accuracies through it)."""
        sample = self.client.latest(key)
        if si(sample) is None or self.client.is_stale(key):
            return None
        return sample

    def _unseen(self, name: str, sample: Sample) -> bool:
        """True once per arrival of `sample` under `name` (each reading is handed out once)."""
        if self._published.get(name) == sample.received:
            return False
        self._published[name] = sample.received
        return True

    def new_fix(self) -> GnssFix | None:
        """The base GNSS position if a new one arrived since the last call (stale: fresh
        False, so a consumer sees the fix go away)."""
        client = self.client
        latitude, longitude = client.latest("latitude"), client.latest("longitude")
        if latitude is None or longitude is None or si(latitude) is None \
                or si(longitude) is None or not self._unseen("fix", latitude):
            return None
        altitude = client.latest("altitude_msl")
        accuracy = client.latest("position_accuracy")
        lat, lon, alt = si(latitude), si(longitude), si(altitude)
        assert lat is not None and lon is not None  # checked above
        return GnssFix(
            stamp=latitude.stamp, latitude=lat, longitude=lon,
            altitude=alt if alt is not None else math.nan, accuracy=si(accuracy),
            fresh=not (client.is_stale("latitude") or client.is_stale("longitude")))

    def new_heading(self, key: str) -> Heading | None:
        """A fresh `rover_heading` or `global_yaw` not handed out before; the accuracy is
        the rover GNSS's (7.3.2) while that is fresh."""
        sample = self.fresh(key)
        if sample is None or not self._unseen(key, sample):
            return None
        heading = si(sample)
        assert heading is not None  # fresh() hands out numeric samples only
        accuracy = self.fresh("rover_heading_accuracy")
        return Heading(sample.stamp, heading, si_magnitude(accuracy))

    def new_utc(self) -> tuple[float, float] | None:
        """(arrival, UTC seconds) of a fresh base-GNSS time not handed out before."""
        sample = self.client.latest("utc_time")
        if sample is None or self.client.is_stale("utc_time") \
                or not self._unseen("utc_time", sample):
            return None
        value = sample.value
        if isinstance(value, bool) or not isinstance(value, int | float):
            return None  # the ICD's utc_time is a number; anything else is no time
        return sample.stamp, float(value)

    def inclination(self) -> Inclination | None:
        pitch, roll = self.client.latest("global_pitch"), self.client.latest("global_roll")
        if pitch is None or roll is None or self.client.is_stale("global_pitch"):
            return None
        roll_si, pitch_si = si(roll), si(pitch)
        if roll_si is None or pitch_si is None:
            return None
        return Inclination(pitch.stamp, roll_si, pitch_si)

    def zoom(self) -> float | None:
        """Camera0 zoom position (counts) while fresh."""
        sample = self.fresh("zoom_position")
        return si(sample)

"""Errors raised by the kOS codec. Every decoder raises only ProtocolError subclasses."""


class ProtocolError(ValueError):
    """Base class of every error the kOS codec raises."""


class DecodeError(ProtocolError):
    """Bytes that cannot be decoded (truncated payload, bad header, trailing bytes)."""


class EncodeError(ProtocolError):
    """A value that cannot be put on the wire (out of range, not finite, too long)."""


class TrajectoryError(ProtocolError):
    """TrajectoryData that breaks one of the document's rules (see trajectory.validate)."""

"""The codec's own error type: every decoding/encoding problem raises CodecError."""


class CodecError(ValueError):
    """A frame or value that does not follow the CANaerospace ICD (message says why)."""

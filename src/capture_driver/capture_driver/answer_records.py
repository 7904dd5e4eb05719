"""What the answer book (:mod:`.answers`) keeps of each written Capture request, and how
requests are named (no ROS, no I/O)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from .protocol import Frame, ReplyByte

#: a request to write: (command name for messages, its frame, True when it takes data)
Request = tuple[str, Frame, bool]
Item = Frame | ReplyByte


def is_greeting(item: Frame) -> bool:
    """The controller's COM_Connect packet (section 6.1): sent on its own, never an answer."""
    return 0x0700 <= item.opcode <= 0x07FF and not item.data


@dataclass(eq=False)
class Exchange:
    """One write: its requests, and for a byte-answered one the bytes it owns."""

    waitings: list[Waiting] = field(default_factory=list)
    byte: bool = False
    #: a stop's: never preempted by another stop
    urgent: bool = False
    #: owns every byte that comes while it is in flight (a stop written over late answers)
    whole: bool = False
    received: list[ReplyByte] = field(default_factory=list)
    #: bytes that came while a NACK its next request may own is held (None: counting)
    pending: list[ReplyByte] | None = None
    #: why the bytes of this exchange cannot be given one by one ('' when they can)
    doubt: str = ''
    #: called once, on the reader thread, when every request of it has its answer (a
    #: read that does not wait: :meth:`~.batch.BatchedReads.ask_many`)
    on_answered: Callable[[list[Waiting]], None] | None = None


@dataclass(eq=False)
class Waiting:
    """One written request until it has its answer (or gives up)."""

    name: str
    frame: Frame
    expect_data: bool
    #: a getter that answers data or nothing (see the module docstring); setters: False
    data_answered: bool
    written_at: float = 0.0
    seq: int = 0
    exchange: Exchange = field(default_factory=Exchange)
    #: what answered it: its data packet or a reply byte (None: nothing yet)
    answer: Item | None = None
    #: the first answer of the wrong kind that came while it alone waited
    unexpected: str = ''
    #: why its answer is not certainly its own ('' when it is)
    doubt: str = ''
    #: a stop went out while it waited: a byte can no longer be told to be its own (a
    #: setter gives up at once; a getter still takes its data)
    superseded: bool = False
    #: written under the link lock: a stop would wait for it, so a stop preempts it
    holds_lock: bool = False
    error: BaseException | None = None
    done: bool = False
    #: when its wait ended without an answer (its late answer may come until + window)
    ended_at: float | None = None

    #: (opcode, axis): read many times per answer, so computed once
    key: tuple[int, int] = field(init=False)

    def __post_init__(self) -> None:
        self.key = frame_key(self.frame)


@dataclass(eq=False)
class Held:
    """A NACK more than one request could own, until one candidate is left."""

    byte: ReplyByte
    candidates: list[Waiting]
    #: the batch whose counting waits for it (its later bytes are its ``pending``)
    batch: Exchange | None = None


def frame_key(frame: Frame) -> tuple[int, int]:
    return frame.opcode, frame.axis


def label(request: Request) -> str:
    """How a request is named in its errors: the command, and the axis if it has one."""
    name, frame, _ = request
    return f'{name} (axis {frame.axis})' if frame.axis else name

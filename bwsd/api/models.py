"""Request and response bodies of the REST API (they make the OpenAPI schema)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

CommandName = Literal[
    "reset", "start", "stop", "hold", "unhold", "suspend", "unsuspend", "abort", "clear"
]
XYZ = tuple[float, float, float]
MAX_PROGRAM_CHARS = 1_000_000
MAX_REASON_CHARS = 500
MAX_BODY_BYTES = 4 * MAX_PROGRAM_CHARS + 65536  # a program of 4-byte characters, and the JSON


class Error(BaseModel):
    """Every error: what is wrong (other fields by case, see docs/api.md)."""

    error: str


class InvalidOut(Error):
    """A malformed request: the fields at fault, as the validator names them."""

    details: list[dict[str, Any]]


class ProgramErrorOut(Error):
    """A program refused: the message and where (line and column, 1-based; 0: unknown)."""

    line: int
    column: int


class CommandErrorOut(Error):
    """A command the current state does not take, and those it does."""

    state: str
    allowed: list[str]


ModeName = Literal["production", "maintenance", "manual"]


class BusHealth(BaseModel):
    """What the daemon last saw of the machine over the bus (None: not seen yet)."""

    connected: bool | None = None
    last_error: str | None = Field(None, description="the last failure; cleared by a good read")
    checked: float | None = Field(None, description="Unix time of the last observation")
    estop: bool | None = Field(None, description="the emergency stop is pressed")
    faulted: list[str] = Field([], description="axes reporting a fault")
    differs: list[tuple[int, int]] = Field(
        [], description="cells where the occupancy sensors differ from the twin (at rest)"
    )


class NextOut(BaseModel):
    """The instruction the program runs next."""

    index: int = Field(description="its number (1-based)")
    line: int = Field(description="its line in the program text")
    instruction: dict[str, Any] = Field(description="as in the preview's `instruction`")


class StateOut(BaseModel):
    state: int = Field(description="PackML state number (ISA-TR88.00.02)")
    name: str
    mode: int
    mode_name: str
    program_id: int | None
    program_name: str | None
    index: int = Field(description="instructions done of the loaded program")
    count: int = Field(description="instructions in the loaded program")
    reason: str = Field(description="why the machine stopped, held, suspended or aborted")
    stop_cause: str = Field(
        description="the cause of the last stop: none, refused_move, "
        "drive_fault, estop, bus, mismatch, operator, restart, internal, journal"
    )
    allowed: list[str] = Field(description="exactly the commands that will be accepted now")
    recovering: str = Field(description="why commands wait after a restart ('' if they do not)")
    resumable: bool = Field(
        False,
        description="start with resume continues the loaded "
        "program where an Abort or a Stop left it",
    )
    resume_allowed: bool = Field(
        False, description="start with resume will be accepted now (as allowed for the others)"
    )
    manual: str = Field(
        "", description="why no manual move is taken now ('' when they are: POST /manual)"
    )
    bus: BusHealth
    last_fault: str | None = Field(description="the controller's last fault report, if any")
    next: NextOut | None = Field(description="the instruction to run next; null if none")


class AxisOut(BaseModel):
    index: int
    name: str
    kind: str
    position: int = Field(description="micrometres (millidegrees for weft_angle)")
    setpoint: int | None = Field(
        None,
        description="the last set-point the daemon wrote (a stroke for a relative axis, a "
        "position for an absolute one; 0 after homing); null: none since it started",
    )
    relative: bool = Field(False, description="a relative axis: strokes that end back home")
    busy: bool
    fault: int
    fault_name: str


class MachineOut(BaseModel):
    axes: list[AxisOut]
    occupancy: list[list[bool]] = Field(description="the occupancy sensors, by row")
    estop: bool
    read_at: float = Field(description="when the bus answered this read (Unix time)")
    connected: bool = Field(description="the bus answers now (false: this is the last read)")
    twin_occupancy: list[list[int]] | None = Field(
        description="yarn id of the case in each cell per the twin, -1 where empty"
    )


class ProgramIn(BaseModel):
    name: str = Field(min_length=1, max_length=200)
    text: str = Field(max_length=MAX_PROGRAM_CHARS)


class LoadedOut(BaseModel):
    """The dry run of a program: just loaded, or only checked (``dry_run``: no id)."""

    id: int | None = Field(description="the journal's id; null for a dry run")
    name: str
    instructions: int
    contacts: int
    yarns: int
    nodes: int
    takeup: float


class ProgramOut(BaseModel):
    id: int
    name: str
    sha256: str
    instructions: int
    done: int
    created: float
    started: float | None
    finished: float | None
    outcome: str
    reason: str


class OutcomeTotal(BaseModel):
    programs: int
    run_s: float = Field(description="seconds from their first start to their end (holds included)")


class TotalsOut(BaseModel):
    """The journal's programs counted by outcome, with their run time."""

    outcomes: dict[str, OutcomeTotal] = Field(
        description="by outcome: loaded, running, held, suspended, complete, aborted, stopped"
    )
    programs: int
    run_s: float


class LogLineOut(BaseModel):
    seq: int = Field(description="1, 2, ... since the daemon started")
    at: float
    level: str = Field(description="INFO, WARNING, ERROR or CRITICAL")
    logger: str
    message: str = Field(description="the record's first line, at most 2000 characters")
    refusal: bool = Field(description="a request refused by the gate or the controller")


class LogOut(BaseModel):
    lines: list[LogLineOut]
    last: int = Field(description="the number of the newest line the daemon has logged")


class ProgramDetailOut(ProgramOut):
    text: str


class CommandIn(BaseModel):
    reason: str = Field("", max_length=MAX_REASON_CHARS)
    resume: bool = Field(
        False,
        description="with start: continue the loaded program where "
        "an Abort or a Stop left it (see resumable in the state)",
    )


class ModeIn(BaseModel):
    mode: ModeName


class ManualIn(BaseModel):
    kind: Literal["stroke", "takeup", "reset_faults"]
    axis: str | None = Field(None, max_length=40, description="stroke: a row, column or segment")
    step: int | None = Field(None, description="stroke: +1 or -1 cell")
    length: float | None = Field(None, description="takeup: mm, -50 to 50, not 0")


class ManualOut(BaseModel):
    done: str = Field(description="what was done (stroke row1 +1, take-up +2 mm, fault reset)")
    machine: MachineOut = Field(description="the machine as read back after it")


class WhoOut(BaseModel):
    """The holder of the request's token, and its role."""

    name: str = Field(description="the token's name (`anonymous`: an open read without one)")
    role: Literal["viewer", "operator", "admin"]


class ModeOut(BaseModel):
    mode: int
    mode_name: str


class CommandOut(BaseModel):
    state: int
    name: str
    reason: str
    allowed: list[str]


class ContactOut(BaseModel):
    yarns: tuple[int, int] = Field(description="moving yarn, hit yarn")
    nodes: tuple[int, int] = Field(description="node added to each")


class NodeOut(BaseModel):
    yarn: int
    node: int
    after: int = Field(description="the node it follows in the yarn")
    xyz: XYZ


class FreeNodeOut(BaseModel):
    yarn: int
    xyz: XYZ


class LengthOut(BaseModel):
    yarn: int
    change: float = Field(description="mm, change of the warp's path length")


class PreviewOut(BaseModel):
    index: int = Field(description="the instruction previewed (1-based)")
    line: int = Field(description="its line in the program text (0: unknown)")
    instruction: dict[str, Any]
    refused: str | None = Field(description="why the controller would refuse it, if it would")
    contacts: list[ContactOut]
    inserted: list[NodeOut]
    free_nodes: list[FreeNodeOut]
    occupancy: list[list[int]]
    takeup: float
    new_yarns: list[int]
    length_change: list[LengthOut]


class StateRecordOut(BaseModel):
    id: int
    time: float
    state: int
    name: str
    reason: str


class EventRecordOut(BaseModel):
    id: int
    time: float
    kind: str
    data: dict[str, Any]


class HistoryOut(BaseModel):
    states: list[StateRecordOut]
    events: list[EventRecordOut]


class Health(BaseModel):
    ok: bool = Field(description="false (and HTTP 503) while a part of the daemon is down")
    open_reads: bool = Field(description="reads are served without a token")
    problems: dict[str, str] = Field(
        default_factory=dict, description="what is down, by part: a task, the recovery, the journal"
    )
    boot: str = Field(description="this start of the daemon: another value, it restarted")
    started: float = Field(description="when this start began (Unix time)")


Responses = dict[int | str, dict[str, Any]]
AUTH_ERRORS: Responses = {401: {"model": Error}, 403: {"model": Error}}
INVALID: Responses = {422: {"model": InvalidOut}}
BODY_ERRORS: Responses = {400: {"model": Error}, 413: {"model": Error}}  # unreadable, too large

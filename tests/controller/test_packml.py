"""The PackML state machine against a transition table written out here, independently."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bwsd.controller import (
    ACTING,
    MODE_CHANGE_STATES,
    WAITING,
    Command,
    InvalidCommand,
    InvalidEvent,
    InvalidModeChange,
    PackML,
    PackMLError,
    State,
    UnitMode,
)
from bwsd.errors import BwsdError

# Rows: current state; columns: commands; cell: next state, "-" when refused.
TABLE = """
state        Reset     Start    Stop     Hold    Unhold    Suspend    Unsuspend    Abort    Clear
Clearing     -         -        -        -       -         -          -            Aborting -
Stopped      Resetting -        -        -       -         -          -            Aborting -
Starting     -         -        Stopping Holding -         -          -            Aborting -
Idle         -         Starting Stopping -       -         -          -            Aborting -
Suspended    -         -        Stopping Holding -         -          Unsuspending Aborting -
Execute      -         -        Stopping Holding -         Suspending -            Aborting -
Stopping     -         -        -        -       -         -          -            Aborting -
Aborting     -         -        -        -       -         -          -            -        -
Aborted      -         -        -        -       -         -          -            -        Clearing
Holding      -         -        Stopping -       -         -          -            Aborting -
Held         -         -        Stopping -       Unholding -          -            Aborting -
Unholding    -         -        Stopping Holding -         -          -            Aborting -
Suspending   -         -        Stopping Holding -         -          -            Aborting -
Unsuspending -         -        Stopping Holding -         -          -            Aborting -
Resetting    -         -        Stopping -       -         -          -            Aborting -
Completing   -         -        Stopping -       -         -          -            Aborting -
Complete     Resetting -        Stopping -       -         -          -            Aborting -
"""

NUMBERS = {
    "Clearing": 1,
    "Stopped": 2,
    "Starting": 3,
    "Idle": 4,
    "Suspended": 5,
    "Execute": 6,
    "Stopping": 7,
    "Aborting": 8,
    "Aborted": 9,
    "Holding": 10,
    "Held": 11,
    "Unholding": 12,
    "Suspending": 13,
    "Unsuspending": 14,
    "Resetting": 15,
    "Completing": 16,
    "Complete": 17,
}
COMMAND_NUMBERS = {
    "Reset": 1,
    "Start": 2,
    "Stop": 3,
    "Hold": 4,
    "Unhold": 5,
    "Suspend": 6,
    "Unsuspend": 7,
    "Abort": 8,
    "Clear": 9,
}

COMPLETES = {
    "Resetting": "Idle",
    "Starting": "Execute",
    "Completing": "Complete",
    "Holding": "Held",
    "Unholding": "Execute",
    "Suspending": "Suspended",
    "Unsuspending": "Execute",
    "Stopping": "Stopped",
    "Aborting": "Aborted",
    "Clearing": "Stopped",
}


def parse_table() -> dict[tuple[str, str], str | None]:
    header, *rows = TABLE.strip().splitlines()
    commands = header.split()[1:]
    cells: dict[tuple[str, str], str | None] = {}
    for row in rows:
        state, *targets = row.split()
        assert len(targets) == len(commands), row
        for command, target in zip(commands, targets, strict=True):
            cells[state, command] = None if target == "-" else target
    return cells


CELLS = parse_table()
S = {name: State(number) for name, number in NUMBERS.items()}
C = {name: Command(number) for name, number in COMMAND_NUMBERS.items()}


def machine(state: str, mode: UnitMode = UnitMode.PRODUCTION) -> PackML:
    return PackML(S[state], mode)


def test_table_covers_every_state_and_command():
    assert {s for s, _ in CELLS} == set(NUMBERS)
    assert {c for _, c in CELLS} == set(COMMAND_NUMBERS)
    assert len(CELLS) == 17 * 9


def test_standard_numbers():
    assert {s.label: int(s) for s in State} == NUMBERS
    assert {c.label: int(c) for c in Command} == COMMAND_NUMBERS
    assert {m.label: int(m) for m in UnitMode} == {"Production": 1, "Maintenance": 2, "Manual": 3}


def test_acting_and_waiting_sets():
    assert {s.label for s in ACTING} == {n for n in NUMBERS if n.endswith("ing")}
    assert {s.label for s in WAITING} == {
        "Stopped",
        "Idle",
        "Suspended",
        "Held",
        "Complete",
        "Aborted",
    }
    assert not ACTING & WAITING
    assert set(State) - ACTING - WAITING == {State.EXECUTE}


@pytest.mark.parametrize(("state", "command"), sorted(CELLS))
def test_every_state_and_command(state: str, command: str):
    packml = machine(state)
    expected = CELLS[state, command]
    assert packml.accepts(C[command]) is (expected is not None)
    if expected is None:
        with pytest.raises(InvalidCommand) as info:
            packml.command(C[command])
        assert packml.state is S[state]
        assert info.value.command is C[command] and info.value.state is S[state]
        assert f"{command} is not accepted in state {state}" in str(info.value)
    else:
        assert packml.command(C[command]) is S[expected]
        assert packml.state is S[expected]


@pytest.mark.parametrize("state", sorted(NUMBERS))
def test_allowed_lists_exactly_the_accepted_commands(state: str):
    expected = {c for c in COMMAND_NUMBERS if CELLS[state, c] is not None}
    allowed = machine(state).allowed()
    assert {c.label for c in allowed} == expected
    assert len(allowed) == len(expected)


def test_allowed_order_and_message():
    assert machine("Execute").allowed() == [
        Command.HOLD,
        Command.SUSPEND,
        Command.STOP,
        Command.ABORT,
    ]
    with pytest.raises(InvalidCommand) as info:
        machine("Execute").command(Command.START)
    assert str(info.value) == (
        "Start is not accepted in state Execute (accepted there: Hold, Suspend, Stop, Abort)"
    )
    with pytest.raises(InvalidCommand, match=r"accepted there: none"):
        machine("Aborting").command(Command.CLEAR)


def test_errors_are_bwsd_errors():
    assert issubclass(InvalidCommand, PackMLError)
    for error in (InvalidCommand, InvalidEvent, InvalidModeChange):
        assert issubclass(error, BwsdError)


@pytest.mark.parametrize("state", sorted(NUMBERS))
def test_stop_rule(state: str):
    refused = {"Stopping", "Stopped", "Clearing", "Aborting", "Aborted"}
    packml = machine(state)
    assert packml.accepts(Command.STOP) is (state not in refused)
    if state not in refused:
        assert packml.command(Command.STOP) is State.STOPPING


@pytest.mark.parametrize("state", sorted(NUMBERS))
def test_abort_rule(state: str):
    packml = machine(state)
    assert packml.accepts(Command.ABORT) is (state not in {"Aborting", "Aborted"})
    if packml.accepts(Command.ABORT):
        assert packml.command(Command.ABORT) is State.ABORTING


@pytest.mark.parametrize("state", sorted(NUMBERS))
def test_state_complete(state: str):
    packml = machine(state)
    if state in COMPLETES:
        assert packml.state_complete() is S[COMPLETES[state]]
        assert packml.state is S[COMPLETES[state]]
    else:
        with pytest.raises(InvalidEvent, match=f"state complete is not possible in state {state}"):
            packml.state_complete()
        assert packml.state is S[state]


@pytest.mark.parametrize("state", sorted(NUMBERS))
def test_execute_done_only_in_execute(state: str):
    packml = machine(state)
    if state == "Execute":
        assert packml.execute_done() is State.COMPLETING
    else:
        with pytest.raises(InvalidEvent, match=r"only in: Execute\)"):
            packml.execute_done()
        assert packml.state is S[state]


def test_full_production_cycle():
    packml = PackML()
    assert (packml.state, packml.mode) == (State.STOPPED, UnitMode.PRODUCTION)
    assert packml.command(Command.RESET) is State.RESETTING
    assert packml.state_complete() is State.IDLE
    assert packml.command(Command.START) is State.STARTING
    assert packml.state_complete() is State.EXECUTE
    assert packml.execute_done() is State.COMPLETING
    assert packml.state_complete() is State.COMPLETE
    assert packml.command(Command.RESET) is State.RESETTING
    assert packml.state_complete() is State.IDLE


def executing() -> PackML:
    packml = machine("Idle")
    packml.command(Command.START)
    packml.state_complete()
    assert packml.state is State.EXECUTE
    return packml


def test_hold_unhold_round_trip():
    packml = executing()
    assert packml.command(Command.HOLD, reason="yarn break") is State.HOLDING
    assert packml.state_complete() is State.HELD
    assert not packml.accepts(Command.START)
    assert packml.command(Command.UNHOLD) is State.UNHOLDING
    assert packml.state_complete() is State.EXECUTE


def test_suspend_unsuspend_round_trip():
    packml = executing()
    assert packml.command(Command.SUSPEND) is State.SUSPENDING
    assert packml.state_complete() is State.SUSPENDED
    assert packml.command(Command.UNSUSPEND) is State.UNSUSPENDING
    assert packml.state_complete() is State.EXECUTE


def test_hold_while_suspended_then_unhold_resumes_execute():
    packml = executing()
    packml.command(Command.SUSPEND)
    packml.state_complete()
    assert packml.command(Command.HOLD) is State.HOLDING
    packml.state_complete()
    packml.command(Command.UNHOLD)
    assert packml.state_complete() is State.EXECUTE


def test_abort_clear_stopped():
    packml = executing()
    assert packml.command(Command.ABORT, reason="e-stop") is State.ABORTING
    assert not packml.accepts(Command.CLEAR)
    assert packml.state_complete() is State.ABORTED
    assert packml.command(Command.CLEAR) is State.CLEARING
    assert packml.state_complete() is State.STOPPED
    assert packml.reason == ""  # cleared: what stopped it is no longer true


def test_abort_while_clearing():
    packml = machine("Aborted")
    packml.command(Command.CLEAR)
    assert packml.command(Command.ABORT) is State.ABORTING


def test_reason_kept_for_stop_abort_hold_suspend_and_cleared_by_every_other_command():
    packml = executing()
    packml.command(Command.HOLD, reason="jam at carrier 3")
    packml.state_complete()
    assert packml.reason == "jam at carrier 3"
    packml.command(Command.UNHOLD, reason="ignored")
    assert packml.reason == ""  # resumed: the jam is no longer why it stands
    packml.state_complete()
    packml.command(Command.SUSPEND, reason="waiting for yarn")
    assert packml.reason == "waiting for yarn"
    packml.state_complete()
    packml.command(Command.STOP, reason="operator")
    assert packml.reason == "operator"
    packml.state_complete()
    packml.command(Command.RESET)
    assert packml.reason == ""


def test_refused_command_keeps_reason():
    packml = machine("Aborted")
    packml.reason = "e-stop"
    with pytest.raises(InvalidCommand):
        packml.command(Command.STOP, reason="other")
    assert packml.reason == "e-stop"


@pytest.mark.parametrize("state", sorted(NUMBERS))
def test_mode_change_only_at_rest(state: str):
    packml = machine(state)
    if state in {"Stopped", "Idle", "Aborted"}:
        packml.set_mode(UnitMode.MANUAL)
        assert packml.mode is UnitMode.MANUAL
    else:
        with pytest.raises(InvalidModeChange, match=f"Manual is not accepted in state {state}"):
            packml.set_mode(UnitMode.MANUAL)
        assert packml.mode is UnitMode.PRODUCTION
    assert packml.state is S[state]


def test_mode_change_states_constant():
    assert {s.label for s in MODE_CHANGE_STATES} == {"Stopped", "Idle", "Aborted"}


def test_same_mode_is_accepted_anywhere():
    packml = executing()
    packml.set_mode(UnitMode.PRODUCTION)
    assert packml.mode is UnitMode.PRODUCTION


def test_modes_run_the_same_state_model():
    packml = machine("Stopped", UnitMode.MAINTENANCE)
    packml.command(Command.RESET)
    packml.state_complete()
    packml.command(Command.START)
    assert packml.state_complete() is State.EXECUTE
    assert packml.mode is UnitMode.MAINTENANCE


def test_listeners_see_every_change_with_its_cause():
    packml = PackML()
    seen: list[tuple[State, State, str]] = []
    other: list[State] = []
    packml.on_change.append(lambda old, new, cause: seen.append((old, new, cause)))
    packml.on_change.append(lambda old, new, cause: other.append(new))
    packml.command(Command.RESET)
    packml.state_complete()
    packml.command(Command.START)
    packml.state_complete()
    packml.command(Command.HOLD, reason="yarn break")
    assert seen == [
        (State.STOPPED, State.RESETTING, "Reset"),
        (State.RESETTING, State.IDLE, "state complete"),
        (State.IDLE, State.STARTING, "Start"),
        (State.STARTING, State.EXECUTE, "state complete"),
        (State.EXECUTE, State.HOLDING, "Hold: yarn break"),
    ]
    assert other == [new for _, new, _ in seen]


def test_listeners_not_called_on_refusals_or_mode_changes():
    packml = machine("Idle")
    seen: list[str] = []
    packml.on_change.append(lambda old, new, cause: seen.append(cause))
    with pytest.raises(InvalidCommand):
        packml.command(Command.HOLD)
    with pytest.raises(InvalidEvent):
        packml.state_complete()
    packml.set_mode(UnitMode.MAINTENANCE)
    assert seen == []


def test_execute_done_cause():
    packml = executing()
    seen: list[str] = []
    packml.on_change.append(lambda old, new, cause: seen.append(cause))
    packml.execute_done()
    assert seen == ["execute done"]


# One step of a random run: a command, "state complete", "execute done" or a mode change.
steps = st.one_of(
    st.sampled_from(list(Command)),
    st.sampled_from(["complete", "done"]),
    st.sampled_from(list(UnitMode)),
)


def apply(packml: PackML, step: Command | UnitMode | str) -> bool:
    """Apply one step; True when the machine accepted it."""
    try:
        if isinstance(step, Command):
            packml.command(step, reason="r")
        elif isinstance(step, UnitMode):
            packml.set_mode(step)
        elif step == "complete":
            packml.state_complete()
        else:
            packml.execute_done()
    except PackMLError:
        return False
    return True


@pytest.mark.slow
@settings(max_examples=300)
@given(start=st.sampled_from(list(State)), run=st.lists(steps, max_size=60))
def test_random_runs_keep_invariants(start: State, run: list[Command | UnitMode | str]):
    packml = PackML(start)
    changes: list[tuple[State, State]] = []
    packml.on_change.append(lambda old, new, cause: changes.append((old, new)))
    for step in run:
        before, mode_before, count = packml.state, packml.mode, len(changes)
        accepted = apply(packml, step)
        assert isinstance(packml.state, State)
        assert isinstance(packml.mode, UnitMode)
        if not accepted:
            assert (packml.state, packml.mode) == (before, mode_before)
            assert len(changes) == count
        elif isinstance(step, Command):
            assert changes[-1] == (before, packml.state)
            assert CELLS[before.label, step.label] == packml.state.label
        if packml.mode is not mode_before:
            assert before.label in {"Stopped", "Idle", "Aborted"}
        assert packml.accepts(Command.ABORT) is (
            packml.state not in {State.ABORTING, State.ABORTED}
        )
    assert all(old is not new for old, new in changes)

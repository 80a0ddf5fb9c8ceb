"""Operator commands (Ueland 2017 §Operator Interaction): explore, go to a location, stop.

Ueland 2017's operator window lets the user "toggle between automatic exploration and navigation to
a known location on the map"; we add stop. A command travels as a 3-vector [mode, goal_x, goal_y]
(``operator_command`` ports), the mode one of :class:`OperatorMode`.
"""

import enum
from dataclasses import dataclass, field

from pydrake.geometry import Cylinder, Rgba
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem


class OperatorMode(enum.IntEnum):
    EXPLORE = 0  # frontier exploration (Ueland 2017 §Exploration Strategy)
    GOTO = 1  # single-goal A* to the operator's location
    STOP = 2  # hold the current position


MODE_NAMES = {m.name.lower(): m for m in OperatorMode}


@dataclass
class OperatorCommandConfig:
    """A scripted operator action: at ``time`` [s] switch to ``mode`` (explore | goto | stop),
    with ``goal`` [x, y] [m] for goto."""

    time: float = 0.0
    mode: str = "explore"
    goal: list[float] = field(default_factory=list)


def parse_mode(name: str) -> OperatorMode:
    """The :class:`OperatorMode` called ``name`` (case-insensitive); ValueError otherwise."""
    try:
        return MODE_NAMES[str(name).lower()]
    except KeyError:
        raise ValueError(
            f"unknown operator mode {name!r}; expected one of {', '.join(MODE_NAMES)}"
        ) from None


BUTTONS = {  # Meshcat button label → (mode, keyboard shortcut)
    "Explore": (OperatorMode.EXPLORE, "KeyE"),
    "Go to goal": (OperatorMode.GOTO, "KeyG"),
    "Stop": (OperatorMode.STOP, "KeyS"),
}
GOAL_SLIDERS = ("Goal x [m]", "Goal y [m]")


class OperatorPanel(LeafSystem):
    """Ueland 2017's operator controls as a LeafSystem: Meshcat buttons (Explore / Go to goal /
    Stop, keys E / G / S) and two goal sliders, and/or a script of timed commands.

    .. pydrake_system::

        name: OperatorPanel
        output_ports:
        - operator_command

    ``operator_command`` = [mode, goal_x, goal_y]. Every 1/``rate_hz`` s the panel applies the
    script's commands that are due and any button clicked since the last poll (the goal is the
    sliders' value at the click), and moves the goal marker (a magenta post) to the sliders.
    ``bounds`` = (xmin, ymin, xmax, ymax) [m] of the sliders.
    """

    def __init__(
        self,
        meshcat=None,
        bounds=(0.0, 0.0, 10.0, 10.0),
        script: list[OperatorCommandConfig] | None = None,
        initial_mode: OperatorMode = OperatorMode.EXPLORE,
        rate_hz: float = 5.0,
    ):
        super().__init__()
        self._meshcat = meshcat
        self._script = sorted(script or [], key=lambda c: c.time)
        for c in self._script:
            if parse_mode(c.mode) == OperatorMode.GOTO and len(c.goal) != 2:
                raise ValueError(f"operator command at t={c.time}: goto needs goal [x, y]")
        xmin, ymin, xmax, ymax = (float(b) for b in bounds)
        goal0 = [(xmin + xmax) / 2, (ymin + ymax) / 2]
        if meshcat is not None:
            for label, (_, key) in BUTTONS.items():
                meshcat.AddButton(label, key)
            for label, lo, hi, v in zip(
                GOAL_SLIDERS, (xmin, ymin), (xmax, ymax), goal0, strict=True
            ):
                meshcat.AddSlider(label, lo, hi, 0.1, v)
            meshcat.SetObject("/operator/goal", Cylinder(0.05, 1.0), Rgba(1.0, 0.1, 0.9, 0.9))
            meshcat.SetTransform("/operator/goal", RigidTransform([*goal0, 0.5]))
        # [mode, gx, gy, script index, clicks per button...]
        self._state = self.DeclareDiscreteState(
            BasicVector([float(initial_mode), *goal0, 0.0] + [0.0] * len(BUTTONS))
        )
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / rate_hz, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "operator_command",
            3,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._state).value()[:3]),
            prerequisites_of_calc={self.discrete_state_ticket(self._state)},
        )

    def _update(self, context, discrete_state):
        s = context.get_discrete_state(self._state).value().copy()
        t = context.get_time()
        i = int(s[3])
        while i < len(self._script) and self._script[i].time <= t + 1e-9:
            c = self._script[i]
            s[0] = float(parse_mode(c.mode))
            if len(c.goal) == 2:
                s[1:3] = c.goal
            i += 1
        s[3] = i
        m = self._meshcat
        if m is not None:
            goal = [m.GetSliderValue(label) for label in GOAL_SLIDERS]
            m.SetTransform("/operator/goal", RigidTransform([*goal, 0.5]))
            for k, (label, (mode, _)) in enumerate(BUTTONS.items()):
                clicks = m.GetButtonClicks(label)
                if clicks > s[4 + k]:
                    s[4 + k] = clicks
                    s[0] = float(mode)
                    if mode == OperatorMode.GOTO:
                        s[1:3] = goal
        discrete_state.get_mutable_vector(self._state).SetFromVector(s)

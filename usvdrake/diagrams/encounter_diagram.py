"""``build_encounter_diagram``: an own ship among the target ships of a DNV traffic situation.

Two sides, as in every usvdrake diagram (docs/architecture.md). The world: the own ship's
plant and autopilot, the target ships on their waypoints (their true states) and the targets'
AIS transponders. The autonomy: route guidance, the AIS tracker and SB-MPC collision
avoidance. The autonomy sees the targets only through ``ais_reports``:

    target_ships ─► ais_transponders ─► ais_tracker ─► sbmpc_colav ─► autopilot ─► own_ship
                     (world)              (autonomy)        ▲ nominal               │ state
                                                    route_guidance ◄────────────────┘

The own ship reads its own state directly (its navigation sensors are taken as exact at this
scale: GNSS metres against a 926 m safety distance). The own ship is a ship-scale model built
from the situation (``ship_model``) or any usvdrake vessel on a Froude-scaled situation.
"""

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Multiplexer

from usvdrake.errors import ConfigError
from usvdrake.systems.colav.ais import AisNoise
from usvdrake.systems.colav.ais_tracker_system import AisTrackerSystem
from usvdrake.systems.colav.ais_transponders import AisTransponders
from usvdrake.systems.colav.route_guidance import RouteGuidance
from usvdrake.systems.colav.sbmpc import NMI, SbmpcParams
from usvdrake.systems.colav.sbmpc_colav import SbmpcColav
from usvdrake.systems.colav.scaling import froude_scaled, placed
from usvdrake.systems.colav.ship_autopilot import ShipAutopilot
from usvdrake.systems.colav.ship_model import (
    ShipParams,
    initial_state,
    response_time_constants,
)
from usvdrake.systems.colav.ship_plant import ShipPlant
from usvdrake.systems.colav.situation import (
    REFERENCE_LENGTH_M,
    TrafficSituation,
    load_situation,
    resolve_situation,
)
from usvdrake.systems.colav.target_ships import TargetShips
from usvdrake.systems.control.heading_speed_controller import HeadingSpeedController
from usvdrake.systems.guidance.line_of_sight import ControlConfig
from usvdrake.systems.vessel.thrust_allocation import ThrustAllocation
from usvdrake.systems.vessel.thrust_mixer import ThrustMixer
from usvdrake.systems.vessel.vessel_plant import VesselPlant
from usvdrake.vessel import VesselParams, load_vessel

SHIP = "ship"  # the own ship built from the situation's dimensions; else a usvdrake vessel
AUTONOMY = ("route_guidance", "ais_tracker", "sbmpc_colav")  # the systems that think
WORLD = ("own_ship", "autopilot", "target_ships", "ais_transponders")


@dataclass(frozen=True)
class EncounterConfig:
    """The knobs of an encounter run (defaults: ship scale, issue 37's 0.5 nmi CPA)."""

    safety_distance_m: float = 0.5 * NMI  # required CPA; SB-MPC keeps 1.3 × this
    seed: int = 0  # AIS noise streams
    ais_period_s: float = 1.0  # transponder and tracker sampling
    colav_period_s: float = 5.0  # SB-MPC re-decision
    autopilot_period_s: float = 1.0
    lookahead_lengths: float = 8.0  # LOS lookahead in own-ship lengths ...
    min_lookahead_m: float = 1000.0  # ... and at least this
    switch_lengths: float = 2.0  # leg switching radius in ship lengths
    # the steepest return to the route [deg] while an encounter is open (None: the guidance's
    # own): capping it at 8° raised COLREG compliance a little but doubled some paths and cut
    # arrivals (docs/experiments/colav-tuning.md)
    max_return_deg: float | None = None
    # within this many LOS lookaheads of the route's end no stand-on duty holds the own ship off
    # its route (``SbmpcColav.end_release``; None: always held)
    end_release_lookaheads: float | None = 4.0
    arrival_radius_m: float = 150.0  # the route is done this close to its end (evaluation: 200)
    length_scale: float = 1.0  # k of a Froude-scaled situation (1: the situation as written)
    # SB-MPC roles from DNV's sectors, as the evaluation classifies (``SbmpcParams.sector_roles``)
    sector_roles: bool = False
    # SB-MPC holds its duties until the target is past and clear (``SbmpcParams.hold_until_clear``)
    hold_until_clear: bool = True

    def froude_scaled(self, k: float) -> "EncounterConfig":
        """Distances × k, times × √k (``scaling.froude_scaled``); AIS sampling unchanged (the
        transponders' intervals are the real ones)."""
        return dataclasses.replace(
            self,
            safety_distance_m=self.safety_distance_m * k,
            colav_period_s=self.colav_period_s * np.sqrt(k),
            min_lookahead_m=self.min_lookahead_m * k,
            arrival_radius_m=self.arrival_radius_m * k,
            length_scale=self.length_scale * k,
        )

    def ais_noise(self) -> AisNoise:
        """AIS noise at this scale: position × k, SOG × √k (our assumption: at canal scale a
        10 m GNSS error would exceed the safety distance; a small boat's AIS-like link would
        carry an RTK-grade position)."""
        base = AisNoise()
        k = self.length_scale
        return dataclasses.replace(
            base, position_m=base.position_m * k, sog_mps=base.sog_mps * np.sqrt(k)
        )


def own_ship_params(situation: TrafficSituation) -> ShipParams:
    """A ship from the situation's own-ship dimensions; its design speed is the first leg's."""
    own = situation.own_ship
    return ShipParams.from_dimensions(
        own.length, own.width, design_speed=own.speed0, ship_type=own.ship_type
    )


def sbmpc_params(ship: ShipParams, safety_distance_m: float) -> SbmpcParams:
    """SB-MPC for this ship: its autopilot's course and speed time constants as the prediction
    model's, the distances scaled to the required CPA."""
    tc, ts = response_time_constants(ship)
    return SbmpcParams.for_safety_distance(
        safety_distance_m, course_time_constant_s=tc, speed_time_constant_s=ts
    )


def vessel_sbmpc_params(control: ControlConfig, cfg: EncounterConfig) -> SbmpcParams:
    """SB-MPC for a usvdrake vessel under the heading/speed controller: the prediction's time
    constants are the controller's design ones (critically damped heading at ω_ψ reaches 63 %
    of a step at ≈ 2.15/ω_ψ; the surge loop is first order at its bandwidth), the horizon and
    step scaled by √k from the ship-scale defaults."""
    tk = np.sqrt(cfg.length_scale)
    base = SbmpcParams()
    return SbmpcParams.for_safety_distance(
        cfg.safety_distance_m,
        course_time_constant_s=2.15 / control.heading_natural_frequency,
        speed_time_constant_s=1.0 / control.surge_bandwidth,
        horizon_s=base.horizon_s * tk,
        dt_s=base.dt_s * tk,
        min_target_speed=base.min_target_speed * tk,
    )


def _add_ship(b, situation: TrafficSituation, cfg: EncounterConfig):
    """Clarke 1983 ship + autopilot; returns (state port, command port, length, SB-MPC params)."""
    route = situation.own_ship
    ship = own_ship_params(situation)
    q0 = initial_state(ship, *route.xy[0], psi=route.psi0, speed=route.speed0)
    plant = b.AddNamedSystem("own_ship", ShipPlant(ship, q0))
    pilot = b.AddNamedSystem(
        "autopilot", ShipAutopilot(ship, cfg.autopilot_period_s, initial_speed=route.speed0)
    )
    b.Connect(pilot.GetOutputPort("actuator_command"), plant.GetInputPort("actuator_command"))
    b.Connect(plant.GetOutputPort("full_state"), pilot.GetInputPort("full_state"))
    b.ExportOutput(plant.GetOutputPort("full_state"), "own_full_state")
    params = sbmpc_params(ship, cfg.safety_distance_m)
    return plant.GetOutputPort("state"), pilot.GetInputPort("command"), ship.length, params


def _add_vessel(b, vessel: VesselParams, situation: TrafficSituation, cfg: EncounterConfig):
    """A usvdrake vessel (plant, thrusters, allocation, heading/speed controller) as own ship."""
    route = situation.own_ship
    x0, y0 = route.xy[0]
    plant = b.AddNamedSystem(
        "own_ship", VesselPlant(vessel, [x0, y0, route.psi0, route.speed0, 0.0, 0.0])
    )
    mixer = b.AddNamedSystem("thrust_mixer", ThrustMixer(vessel.thrusters))
    allocation = b.AddNamedSystem("thrust_allocation", ThrustAllocation(vessel))
    control = ControlConfig()
    pilot = b.AddNamedSystem("autopilot", HeadingSpeedController(vessel.hydrodynamics, control))
    # The controller's reference is [ψ_d, u_d, e]: the command with no cross-track term.
    reference = b.AddNamedSystem("reference", Multiplexer([2, 1]))
    zero = b.AddNamedSystem("no_cross_track", ConstantVectorSource([0.0]))
    b.Connect(zero.get_output_port(), reference.get_input_port(1))
    b.Connect(reference.get_output_port(), pilot.GetInputPort("reference"))
    b.Connect(plant.GetOutputPort("state"), pilot.GetInputPort("state_estimate"))
    b.Connect(pilot.GetOutputPort("tau_desired"), allocation.GetInputPort("tau_desired"))
    b.Connect(allocation.GetOutputPort("thruster_command"), mixer.GetInputPort("thruster_command"))
    b.Connect(mixer.GetOutputPort("tau"), plant.GetInputPort("tau"))
    params = vessel_sbmpc_params(control, cfg)
    return plant.GetOutputPort("state"), reference.get_input_port(0), vessel.hull.length, params


def build_encounter_diagram(
    situation: TrafficSituation,
    own: str = SHIP,
    config: EncounterConfig | None = None,
    sbmpc: SbmpcParams | None = None,
    ais_noise: AisNoise | None = None,
) -> Diagram:
    """The closed loop of one traffic situation. ``own``: ``"ship"`` (a Clarke 1983 ship from the
    situation's own-ship dimensions, ``own_ship_params``, with ``ShipAutopilot``) or a usvdrake
    vessel name or YAML (``roboat2``: its plant, thrusters and heading/speed controller; give
    it a situation at its scale, ``scaling.froude_scaled``, and ``config.froude_scaled``).
    ``sbmpc``: default ``sbmpc_params`` (ship) or ``vessel_sbmpc_params``; ``ais_noise``:
    default ``config.ais_noise()``.

    Exported outputs: ``own_state`` [x y ψ u v r] (and for the ship ``own_full_state``, + δ, n),
    ``target_states`` ([x y ψ speed] per target, truth), ``track_states``, ``nominal``,
    ``command``, ``colav_diagnostics``, ``mission_complete``."""
    cfg = config or EncounterConfig()
    route = situation.own_ship
    if len(route.xy) < 2:
        raise ConfigError(
            situation.source or "situation", "ownShip.waypoints", "at least two", len(route.xy)
        )
    noise = ais_noise or cfg.ais_noise()
    b = DiagramBuilder()
    if own == SHIP:
        state, command, length, params = _add_ship(b, situation, cfg)
    else:
        state, command, length, params = _add_vessel(b, load_vessel(own), situation, cfg)
    targets = b.AddNamedSystem("target_ships", TargetShips(situation.targets))
    ais = b.AddNamedSystem(
        "ais_transponders", AisTransponders(targets.ids, cfg.seed, noise, cfg.ais_period_s)
    )
    lookahead = max(cfg.lookahead_lengths * length, cfg.min_lookahead_m)
    guidance = b.AddNamedSystem(
        "route_guidance",
        RouteGuidance(
            route.xy,
            route.leg_speeds,
            lookahead=lookahead,
            switch_radius=cfg.switch_lengths * length,
            arrival_radius=cfg.arrival_radius_m,
        ),
    )
    tracker = b.AddNamedSystem(
        "ais_tracker", AisTrackerSystem(len(situation.targets), noise, cfg.ais_period_s)
    )
    colav = b.AddNamedSystem(
        "sbmpc_colav",
        SbmpcColav(
            sbmpc
            or dataclasses.replace(
                params, sector_roles=cfg.sector_roles, hold_until_clear=cfg.hold_until_clear
            ),
            cfg.colav_period_s,
            None if cfg.max_return_deg is None else np.radians(cfg.max_return_deg),
            None if cfg.end_release_lookaheads is None else cfg.end_release_lookaheads * lookahead,
            destination=route.xy[-1],
            arrival_radius=cfg.arrival_radius_m,
            end_leg_start=route.xy[-2],
        ),
    )
    b.Connect(targets.GetOutputPort("target_states"), ais.GetInputPort("target_states"))
    b.Connect(ais.GetOutputPort("ais_reports"), tracker.GetInputPort("ais_reports"))
    b.Connect(state, guidance.GetInputPort("state"))
    b.Connect(state, colav.GetInputPort("state"))
    b.Connect(guidance.GetOutputPort("nominal"), colav.GetInputPort("nominal"))
    b.Connect(guidance.GetOutputPort("path_course"), colav.GetInputPort("path_course"))
    b.Connect(guidance.GetOutputPort("distance_to_end"), colav.GetInputPort("distance_to_end"))
    b.Connect(tracker.GetOutputPort("tracks"), colav.GetInputPort("tracks"))
    b.Connect(colav.GetOutputPort("command"), command)
    b.ExportOutput(state, "own_state")
    for system, port, name in (
        (targets, "target_states", "target_states"),
        (tracker, "track_states", "track_states"),
        (guidance, "nominal", "nominal"),
        (colav, "command", "command"),
        (colav, "colav_diagnostics", "colav_diagnostics"),
        (guidance, "mission_complete", "mission_complete"),
    ):
        b.ExportOutput(system.GetOutputPort(port), name)
    diagram = b.Build()
    diagram.set_name("encounter")
    return diagram


def route_time(situation: TrafficSituation) -> float:
    """Time [s] the own ship's route takes at its planned leg speeds."""
    own = situation.own_ship
    legs = np.linalg.norm(np.diff(own.xy, axis=0), axis=1)
    return float(np.sum(legs / np.maximum(own.leg_speeds[: len(legs)], 1e-3)))


# ------------------------------------------------------------------ traffic in a mission


def mission_traffic(name: str, vessel: VesselParams, initial_state) -> TrafficSituation:
    """A scenario's ``traffic.situation`` in its world: Froude-scaled to the vessel's hull when
    its own ship has another length (``scaling.froude_scaled``), then placed so that its own
    ship starts at the scenario's initial pose [x y ψ] (``scaling.placed``)."""
    situation = load_situation(resolve_situation(name))
    k = vessel.hull.length / situation.own_ship.length
    if abs(k - 1.0) > 1e-9:
        situation = froude_scaled(situation, k, vessel.hull.length, vessel.hull.beam)
    x0, y0, psi0 = (float(v) for v in initial_state[:3])
    return placed(situation, x0, y0, psi0)


def add_traffic(b, situation: TrafficSituation, length: float, seed: int, ais_period: float):
    """Target ships (world side: their true states and AIS transponders) and the AIS tracker
    (autonomy side) into builder ``b``; exports ``target_states`` (truth, for the metrics and
    drawing), ``tracks`` (a list of ``tracking.Track``) and ``track_states``. AIS noise at the
    own ship's scale: ``EncounterConfig.ais_noise`` with k = length / 122 m."""
    noise = EncounterConfig(length_scale=length / REFERENCE_LENGTH_M).ais_noise()
    targets = b.AddNamedSystem("traffic", TargetShips(situation.targets))
    ais = b.AddNamedSystem(
        "ais_transponders", AisTransponders(targets.ids, seed, noise, ais_period)
    )
    tracker = b.AddNamedSystem(
        "ais_tracker", AisTrackerSystem(len(situation.targets), noise, ais_period)
    )
    b.Connect(targets.GetOutputPort("target_states"), ais.GetInputPort("target_states"))
    b.Connect(ais.GetOutputPort("ais_reports"), tracker.GetInputPort("ais_reports"))
    b.ExportOutput(targets.GetOutputPort("target_states"), "target_states")
    b.ExportOutput(tracker.GetOutputPort("tracks"), "tracks")
    b.ExportOutput(tracker.GetOutputPort("track_states"), "track_states")

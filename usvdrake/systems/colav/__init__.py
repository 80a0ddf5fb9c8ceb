"""Collision avoidance among ships under COLREGs (issue 37), verified on DNV's standard encounters.

Modules (plain numpy/scipy cores unless stated):

- ``situation`` — DNV ``trafficgen`` traffic-situation JSON and ``encounter_settings.json`` →
  dataclasses in our local ENU world frame; heading and speed unit conversions.
- ``encounter`` — COLREG encounter classification (Rules 13-15, trafficgen's sectors) and the
  closest point of approach (closed form and over sampled tracks).
- ``hull`` — ship hull rectangles and their overlap (collision) test.
- ``evaluation`` — per-target and per-situation evaluation of a finished encounter (CPA,
  collision, COLREG compliance, arrival, path length) and the CSV / JSON outputs.

Further cores: ``ship_model`` (the ship-scale own ship), ``ais`` (AIS class A reports),
``tracking`` (a Kalman filter per AIS target), ``sbmpc`` (Scenario-Based MPC), ``route_los``
(the own ship's LOS course), ``scaling`` (Froude scaling of a situation for a small own ship).
Their LeafSystem shells, one per module: ``ship_plant.ShipPlant``,
``ship_autopilot.ShipAutopilot``, ``route_guidance.RouteGuidance``, ``target_ships.TargetShips``,
``ais_transponders.AisTransponders`` (world side), ``ais_tracker_system.AisTrackerSystem`` and
``sbmpc_colav.SbmpcColav`` (autonomy side); ``usvdrake.diagrams.encounter_diagram`` wires them.

The package data (``data/``) holds ``encounter_settings.json`` and the 40 situations of DNV's
standard encounter set (see ``data/README.md``).
"""

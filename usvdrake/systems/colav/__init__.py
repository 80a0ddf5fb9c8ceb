"""Collision avoidance among ships under COLREGs (issue 37), verified on DNV's standard encounters.

Modules (plain numpy/scipy cores unless stated):

- ``situation`` — DNV ``trafficgen`` traffic-situation JSON and ``encounter_settings.json`` →
  dataclasses in our local ENU world frame; heading and speed unit conversions.
- ``encounter`` — COLREG encounter classification (Rules 13-15, trafficgen's sectors) and the
  closest point of approach (closed form and over sampled tracks).
- ``hull`` — ship hull rectangles and their overlap (collision) test.
- ``evaluation`` — per-target and per-situation evaluation of a finished encounter (CPA,
  collision, COLREG compliance, arrival, path length) and the CSV / JSON outputs.

The package data (``data/``) holds a copy of ``encounter_settings.json`` and a few situations of
DNV's standard encounter set (see ``data/README.md``).
"""

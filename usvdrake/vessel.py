"""Vessel descriptions as typed data (hull, hydrodynamic parameters ξ, thrusters).

The YAML files live in ``usvdrake/vessels/``; ``load_vessel("roboat2")`` reads one into a
:class:`VesselParams`. Frames: body x forward, y left (port), z up (DESIGN.md); the papers'
NED-style matrices are converted once, in the YAML comments and in ``thrusters.py``.
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from usvdrake.typed_yaml import ConfigError, load_typed, resolve_yaml

VESSEL_DIR = Path(__file__).parent / "vessels"


@dataclass
class Hull:
    shape: str = "box"  # "box" (rectangular hull) or "round" (cone-like, Ueland 2017)
    length: float = 1.0  # [m] overall length (top diameter for round hulls)
    beam: float = 0.5  # [m] overall width (top diameter for round hulls)
    height: float = 0.3  # [m] keel to deck
    draught: float = 0.1  # [m] keel to waterline
    bottom_diameter: float = 0.0  # [m] round hulls only: diameter at the keel


@dataclass
class Hydrodynamics:
    """ξ of Roboat II eq. (9): the diagonal inertia (rigid body + added mass) and linear drag."""

    m11: float = 1.0  # [kg] surge inertia incl. added mass
    m22: float = 1.0  # [kg] sway inertia incl. added mass
    m33: float = 1.0  # [kg m^2] yaw inertia incl. added inertia
    Xu: float = 1.0  # [kg/s] linear surge drag
    Yv: float = 1.0  # [kg/s] linear sway drag
    Nr: float = 1.0  # [kg m^2/s] linear yaw drag

    def as_vector(self) -> np.ndarray:
        return np.array([self.m11, self.m22, self.m33, self.Xu, self.Yv, self.Nr])


@dataclass
class Thruster:
    name: str = ""
    x: float = 0.0  # [m] position forward of the centre of origin
    y: float = 0.0  # [m] position to port (left) of the centre of origin
    angle_deg: float = 0.0  # [deg] direction of positive thrust from body x (fixed thrusters)
    azimuth: bool = False  # True: the direction is commanded (force + angle)
    max_force: float = 1.0  # [N] largest forward thrust (the radius of the disc for azimuths)
    min_force: float = -1.0  # [N] largest reverse thrust, negative (azimuths: ignored, 0)


@dataclass
class VesselParams:
    name: str = ""
    description: str = ""
    mass: float = 1.0  # [kg] rigid-body mass (displacement)
    cruise_speed: float = 0.5  # [m/s] nominal service speed
    max_speed: float = 1.0  # [m/s] design top speed
    hull: Hull = field(default_factory=Hull)
    hydrodynamics: Hydrodynamics = field(default_factory=Hydrodynamics)
    thrusters: list[Thruster] = field(default_factory=list)
    # Weights W of the allocation error (τ - Bu)ᵀ W (τ - Bu) for [surge, sway, yaw].
    allocation_weight: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])


def available_vessels() -> list[str]:
    return sorted(p.stem for p in VESSEL_DIR.glob("*.yaml"))


def _validate(params: VesselParams, file: Path) -> VesselParams:
    h = params.hydrodynamics
    for key in ("m11", "m22", "m33", "Xu", "Yv", "Nr"):
        if not getattr(h, key) > 0:
            raise ConfigError(file, f"hydrodynamics.{key}", "a positive number", getattr(h, key))
    if not params.thrusters:
        raise ConfigError(file, "thrusters", "at least one thruster", "none")
    for i, t in enumerate(params.thrusters):
        if not t.max_force > 0:
            raise ConfigError(file, f"thrusters[{i}].max_force", "a positive number", t.max_force)
        if not t.azimuth and t.min_force > t.max_force:
            raise ConfigError(file, f"thrusters[{i}].min_force", "<= max_force", t.min_force)
    if len(params.allocation_weight) != 3 or min(params.allocation_weight) <= 0:
        raise ConfigError(
            file, "allocation_weight", "three positive numbers", params.allocation_weight
        )
    if params.hull.shape not in ("box", "round"):
        raise ConfigError(file, "hull.shape", "'box' or 'round'", repr(params.hull.shape))
    return params


def load_vessel(name_or_path: str | Path) -> VesselParams:
    """Load a shipped vessel by name (``roboat2``, ``usv2000``, ``ntnu_round``) or a YAML path."""
    path = resolve_yaml("vessel", name_or_path, VESSEL_DIR)
    return _validate(load_typed(VesselParams, path), path)

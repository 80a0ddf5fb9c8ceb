"""``SampledLidar``: what Lidar2D and Lidar3D share — one sweep per period, held in the Context."""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.sensors.lidar_model import LidarConfig, LidarModel, Sweep, preset_by_name
from usvdrake.worlds.raycast import Scene
from usvdrake.worlds.solids import box


@dataclass(frozen=True)
class OtherVessels:
    """Vessels that share the water with this lidar's own (a fleet): ``count`` hulls of
    ``length`` × ``beam`` [m] from ``z_min`` to ``z_max`` [m above water], read each sweep from
    the input ``other_vessels`` (their states [x y ψ u v r] stacked, 6·count)."""

    count: int
    length: float  # [m]
    beam: float  # [m]
    z_min: float  # [m] below the waterline: negative
    z_max: float  # [m] deck or canopy top

    def scene(self, states: np.ndarray) -> Scene:
        """The hulls at ``states`` (6·count) as boxes."""
        q = np.asarray(states, float).reshape(self.count, 6)
        hulls = [
            box("vessel", x, y, self.length, self.beam, psi, self.z_min, self.z_max)
            for x, y, psi in q[:, :3]
        ]
        return Scene.from_solids(hulls)


class SampledLidar(LeafSystem):
    """Base class: input ``state`` (the vessel's [x y ψ u v r]); every 1/rate s a periodic
    unrestricted update casts the sweep that ends then and stores the message built by
    ``make_message`` in abstract state, with the sweep counter (the noise step) in discrete
    state; the output port ``port_name`` reads the stored message. ``empty_message(lidar)`` and
    ``make_message(lidar, sweep, time)`` build the subclass's message type. With ``others``
    (a fleet) it also has the input ``other_vessels`` and sees their hulls."""

    def __init__(
        self,
        cfg: LidarConfig,
        scene: Scene,
        seed: int,
        stream: int,
        three_d: bool,
        port_name: str,
        empty_message: Callable[["SampledLidar"], object],
        make_message: Callable[["SampledLidar", Sweep, float], object],
        others: OtherVessels | None = None,
    ):
        super().__init__()
        self._empty, self._make = empty_message, make_message
        preset = preset_by_name(cfg.preset)
        if (len(preset.elevations_deg) > 1) != three_d:
            wanted = "Lidar2D" if three_d else "Lidar3D"
            raise ValueError(f"{type(self).__name__}: preset {cfg.preset!r} is for {wanted}")
        self._model = LidarModel(preset, cfg, scene, seed, stream)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._others, self._others_port = others, None
        if others is not None and others.count > 0:
            self._others_port = self.DeclareVectorInputPort("other_vessels", 6 * others.count)
        self._msg = self.DeclareAbstractState(AbstractValue.Make(self._empty(self)))
        self._seq = self.DeclareDiscreteState(1)
        period = 1.0 / self._model.rate
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, period, self._update)
        self.DeclareStateOutputPort(port_name, self._msg)

    @property
    def period(self) -> float:
        return 1.0 / self._model.rate

    @property
    def model(self) -> LidarModel:
        return self._model

    def _update(self, context, state):
        k = int(context.get_discrete_state(self._seq).GetAtIndex(0))
        movers = None
        if self._others_port is not None:
            movers = self._others.scene(self._others_port.Eval(context))
        sweep = self._model.sweep(self._state.Eval(context), k, movers)
        state.get_mutable_abstract_state(self._msg).set_value(
            self.make_message(sweep, context.get_time())
        )
        state.get_mutable_discrete_state(self._seq).SetAtIndex(0, k + 1)

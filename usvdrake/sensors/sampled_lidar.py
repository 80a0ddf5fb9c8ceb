"""``SampledLidar``: what Lidar2D and Lidar3D share — one sweep per period, held in the Context."""

from collections.abc import Callable

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.sensors.lidar_model import LidarConfig, LidarModel, Sweep, preset_by_name
from usvdrake.sensors.raycast import Scene


class SampledLidar(LeafSystem):
    """Base class: input ``state`` (the vessel's [x y ψ u v r]); every 1/rate s a periodic
    unrestricted update casts the sweep that ends then and stores the message built by
    ``make_message`` in abstract state, with the sweep counter (the noise step) in discrete
    state; the output port ``port_name`` reads the stored message. ``empty_message(lidar)`` and
    ``make_message(lidar, sweep, time)`` build the subclass's message type."""

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
    ):
        super().__init__()
        self._empty, self._make = empty_message, make_message
        preset = preset_by_name(cfg.preset)
        if (len(preset.elevations_deg) > 1) != three_d:
            wanted = "Lidar2D" if three_d else "Lidar3D"
            raise ValueError(f"{type(self).__name__}: preset {cfg.preset!r} is for {wanted}")
        self._model = LidarModel(preset, cfg, scene, seed, stream)
        self._state = self.DeclareVectorInputPort("state", 6)
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
        sweep = self._model.sweep(self._state.Eval(context), k)
        state.get_mutable_abstract_state(self._msg).set_value(
            self.make_message(sweep, context.get_time())
        )
        state.get_mutable_discrete_state(self._seq).SetAtIndex(0, k + 1)

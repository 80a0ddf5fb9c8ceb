"""``AisTransponders``: the targets' class A AIS transponders (world side): true states in,
position reports out (``ais.AisTransmitter``: ITU-R M.1371 intervals, noise, loss)."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.angles import wrap_angle
from usvdrake.systems.colav.ais import AisNoise, AisTransmitter


class AisTransponders(LeafSystem):
    """One AIS transmitter per target, sampled every ``period`` seconds.

    .. pydrake_system::

        name: AisTransponders
        input_ports:
        - target_states
        output_ports:
        - ais_reports

    ``target_states`` = [x y ψ speed] per target (``TargetShips``); ``ais_reports`` = the tuple
    of ``AisReport`` sent at the last sample (each report appears at exactly one sample; a
    receiver tells new ones by their time). The transmitters (report counters, next report
    times) and the previous headings (for the rate of turn that shortens the interval) are
    abstract state, so a cloned context replays the same reports.
    """

    def __init__(self, target_ids, seed: int = 0, noise: AisNoise | None = None, period=1.0):
        super().__init__()
        if not period > 0.0:
            raise ValueError(f"AisTransponders: period must be positive, got {period}")
        self._ids = tuple(int(i) for i in target_ids)
        self._period = float(period)
        self._in = self.DeclareVectorInputPort("target_states", 4 * len(self._ids))
        transmitters = tuple(AisTransmitter(i, seed=seed, noise=noise) for i in self._ids)
        headings = np.full(len(self._ids), np.nan)
        self._tx = self.DeclareAbstractState(AbstractValue.Make((transmitters, headings)))
        self._sent = self.DeclareAbstractState(AbstractValue.Make(()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, 0.0, self._update)
        self.DeclareAbstractOutputPort(
            "ais_reports",
            lambda: AbstractValue.Make(()),
            lambda c, v: v.set_value(c.get_abstract_state(self._sent).get_value()),
            prerequisites_of_calc={self.abstract_state_ticket(self._sent)},
        )

    def _update(self, context, state):
        t = context.get_time()
        truth = self._in.Eval(context).reshape(-1, 4)
        transmitters, last = state.get_mutable_abstract_state(self._tx).get_value()
        sent = []
        for k, tx in enumerate(transmitters):
            x, y, psi, speed = truth[k]
            turn = 0.0 if np.isnan(last[k]) else wrap_angle(psi - last[k]) / self._period
            report = tx.report(t, x, y, speed * np.cos(psi), speed * np.sin(psi), turn)
            if report is not None:
                sent.append(report)
        last[:] = truth[:, 2]
        state.get_mutable_abstract_state(self._sent).set_value(tuple(sent))

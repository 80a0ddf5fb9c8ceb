"""``AisTrackerSystem``: target tracks from AIS reports (autonomy side; ``tracking``)."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.systems.colav.ais import AisNoise
from usvdrake.systems.colav.tracking import AisTracker

TRACK_FIELDS = 5  # [id, east, north, v_east, v_north] per slot of ``track_states``


class AisTrackerSystem(LeafSystem):
    """A constant-velocity Kalman filter per AIS id, fed with the reports it receives.

    .. pydrake_system::

        name: AisTrackerSystem
        input_ports:
        - ais_reports
        output_ports:
        - tracks
        - track_states

    ``ais_reports``: a tuple of ``AisReport`` (new ones are fused at each sample, by their
    time); ``tracks``: the list of ``tracking.Track`` predicted to the present time;
    ``track_states``: for logging, ``slots`` rows of [id x y v_x v_y] in id order, NaN where
    no track is live. The tracker and the time of the last fused report per id are abstract
    state.
    """

    def __init__(
        self, slots: int, noise: AisNoise | None = None, period: float = 1.0, max_age_s=60.0
    ):
        super().__init__()
        if not period > 0.0:
            raise ValueError(f"AisTrackerSystem: period must be positive, got {period}")
        self._slots = int(slots)
        self._in = self.DeclareAbstractInputPort("ais_reports", AbstractValue.Make(()))
        tracker = AisTracker(noise=noise or AisNoise(), max_age_s=max_age_s)
        self._tracker = self.DeclareAbstractState(AbstractValue.Make((tracker, {})))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        deps = {self.abstract_state_ticket(self._tracker), self.time_ticket()}
        self.DeclareAbstractOutputPort(
            "tracks", lambda: AbstractValue.Make([]), self._calc_tracks, deps
        )
        self.DeclareVectorOutputPort(
            "track_states", TRACK_FIELDS * self._slots, self._calc_states, deps
        )

    def _update(self, context, state):
        tracker, fused = state.get_mutable_abstract_state(self._tracker).get_value()
        for report in sorted(self._in.Eval(context), key=lambda r: r.t_s):
            if report.t_s > fused.get(report.target_id, -np.inf):
                tracker.update(report)
                fused[report.target_id] = report.t_s
        tracker.tracks(context.get_time())  # drops the tracks silent for longer than max_age_s

    def _live(self, context):
        tracker, _ = context.get_abstract_state(self._tracker).get_value()
        t = context.get_time()
        return [
            tr.track(t)
            for _, tr in sorted(tracker.trackers.items())
            if t - tr.last_update_s <= tracker.max_age_s
        ]

    def _calc_tracks(self, context, value):
        value.set_value(self._live(context))

    def _calc_states(self, context, output):
        rows = np.full((self._slots, TRACK_FIELDS), np.nan)
        for k, tr in enumerate(self._live(context)[: self._slots]):
            rows[k] = [tr.target_id, *tr.position, *tr.velocity]
        output.SetFromVector(rows.ravel())

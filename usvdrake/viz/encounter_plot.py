"""The picture of one traffic situation, in the style of DNV's situation plots (Sæter et al.
2023): own and target tracks with time marks, the planned route, the hulls to scale at the
start and end, the closest points of approach, and the encounter types in the title."""

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from usvdrake.systems.colav.evaluation import ShipTrack, SituationEvaluation
from usvdrake.systems.colav.hull import Hull, hull_corners
from usvdrake.systems.colav.situation import NAUTICAL_MILE, TrafficSituation

OWN_COLOR = "#1f4e9c"
TARGET_COLORS = ("#c0392b", "#d68910", "#7d3c98", "#148f77", "#7f8c8d")


def _metres(value: float) -> str:
    """A distance [m] to a few significant digits without an exponent."""
    return f"{value:.0f}" if abs(value) >= 100.0 else f"{value:.3g}"


def _hull_patch(hull: Hull, track: ShipTrack, k: int, color: str, unit: float) -> Polygon:
    xy = hull_corners(hull, track.x[k], track.y[k], track.psi[k])[0] / unit
    return Polygon(xy, closed=True, facecolor=color, edgecolor=color, alpha=0.8, zorder=4)


def _marks(ax, track: ShipTrack, color: str, every_s: float, unit: float) -> None:
    """Dots every ``every_s`` seconds along the track, every other one labelled (in minutes,
    or seconds when the marks are less than a minute apart)."""
    times = np.arange(0.0, track.t[-1] + 1e-9, every_s)
    at = track.resample(times)
    ax.plot(at.x / unit, at.y / unit, "o", ms=3, color=color, zorder=3)
    per = 60.0 if every_s >= 60.0 else 1.0
    for k in range(0, len(times), 2):
        ax.annotate(
            f"{times[k] / per:.0f}",
            (at.x[k] / unit, at.y[k] / unit),
            textcoords="offset points",
            xytext=(4, 4),
            fontsize=7,
            color=color,
        )


def plot_encounter(
    path,
    situation: TrafficSituation,
    own: ShipTrack,
    targets: dict,
    evaluation: SituationEvaluation,
    safety_distance_m: float,
    mark_every_s: float = 180.0,
) -> Path:
    """Write the situation's PNG to ``path``: ``targets`` maps target id → ShipTrack (true
    tracks); positions east/north of the own ship's first waypoint in nautical miles (metres
    for a route shorter than 5 km: a Froude-scaled situation), time marks every
    ``mark_every_s`` seconds."""
    unit, unit_name = (
        (NAUTICAL_MILE, "nmi") if situation.own_ship.route_length() > 5e3 else (1.0, "m")
    )
    fig = Figure(figsize=(8, 8))
    ax = fig.add_subplot(1, 1, 1)
    route = situation.own_ship.xy / unit
    ax.plot(route[:, 0], route[:, 1], "--", color="0.6", lw=1, label="own planned route")
    ax.plot(own.x / unit, own.y / unit, color=OWN_COLOR, lw=1.8, label="own")
    _marks(ax, own, OWN_COLOR, mark_every_s, unit)
    own_hull = Hull.from_ship(situation.own_ship)
    ax.add_patch(_hull_patch(own_hull, own, 0, OWN_COLOR, unit))
    ax.add_patch(_hull_patch(own_hull, own, -1, OWN_COLOR, unit))
    verdicts = {e.target_id: e for e in evaluation.targets}
    ships = {s.id: s for s in situation.targets}
    for k, (tid, track) in enumerate(targets.items()):
        color = TARGET_COLORS[k % len(TARGET_COLORS)]
        e = verdicts.get(tid)
        name = f"target {tid}" + (f" ({e.encounter})" if e is not None else "")
        ax.plot(track.x / unit, track.y / unit, color=color, lw=1.4, label=name)
        _marks(ax, track, color, mark_every_s, unit)
        if tid in ships:
            hull = Hull.from_ship(ships[tid])
            ax.add_patch(_hull_patch(hull, track, 0, color, unit))
            ax.add_patch(_hull_patch(hull, track, -1, color, unit))
        if e is None:
            continue
        # The CPA: both ships' positions at its time, joined, with the distance.
        o = own.resample([e.t_cpa_s])
        g = track.resample([e.t_cpa_s])
        ox, oy = o.x[0] / unit, o.y[0] / unit
        gx, gy = g.x[0] / unit, g.y[0] / unit
        ax.plot([ox, gx], [oy, gy], ":", color=color, lw=1.2)
        ax.plot([ox, gx], [oy, gy], "x", color=color, ms=7, mew=2, zorder=5)
        ax.add_patch(
            Circle(
                (ox, oy), safety_distance_m / unit, fill=False, ls="--", lw=0.8,
                edgecolor=color, alpha=0.6,
            )
        )  # fmt: skip
        verdict = "ok" if e.compliant else "NOT compliant"
        ax.annotate(
            f"CPA {_metres(e.cpa_m)} m at {e.t_cpa_s / 60:.1f} min, {verdict}",
            (0.5 * (ox + gx), 0.5 * (oy + gy)),
            textcoords="offset points",
            xytext=(8, -12),
            fontsize=8,
            color=color,
        )
    types = ", ".join(e.encounter for e in evaluation.targets) or "no targets"
    arrived = "arrived" if evaluation.arrived else "did not arrive"
    ax.set_title(
        f"{evaluation.situation}: {types}\n"
        f"min CPA {_metres(evaluation.min_cpa_m)} m, "
        f"{evaluation.compliant}/{evaluation.encounters} compliant, "
        f"{evaluation.collisions} collisions, {arrived}, path × {evaluation.path_ratio:.2f} "
        f"(time marks every {mark_every_s:.0f} s)",
        fontsize=10,
    )
    ax.set_xlabel(f"east [{unit_name}]")
    ax.set_ylabel(f"north [{unit_name}]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.legend(loc="best", fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return path

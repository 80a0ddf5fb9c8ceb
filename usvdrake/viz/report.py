"""``report.html``: the plots a person looks at after a run (trajectory, speed, heading, thrust)."""

import base64
import html
import io
import json

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from usvdrake.systems.vessel.thrusters import command_names
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World

KIND_COLORS = {
    "quay": "#8c735f",
    "wall": "#736659",
    "building": "#a0522d",
    "boat": "#9aa7b8",
    "bridge": "#4d4d52",
    "rock": "#7a756f",
    "tree": "#33692e",
    "bush": "#478537",
    "leaf": "#739e40",
    "bank": "#73664d",
}


def _water_patches(geom):
    polys = list(geom.geoms) if hasattr(geom, "geoms") else [geom]
    for p in polys:
        if not p.is_empty:
            yield np.asarray(p.exterior.coords), [np.asarray(r.coords) for r in p.interiors]


def png_base64(fig, dpi: int = 110) -> str:
    """``fig`` (a :class:`matplotlib.figure.Figure`, no pyplot: the caller's backend, e.g. a
    notebook's inline one, is left alone) as a base64 PNG for ``<img src="data:...">``."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode()


def write_report(
    path,
    title,
    metrics,
    times,
    states,
    reference,
    thrust,
    vessel: VesselParams,
    world: World,
    waypoints,
):
    fig = Figure(figsize=(9, 6))
    ax = fig.subplots()
    wp = np.asarray(waypoints, float).reshape(-1, 2)
    ax.set_facecolor("#d9d6cf")
    for outer, holes in _water_patches(world.water):
        ax.add_patch(Polygon(outer, color="#bcd7ef", zorder=0))
        for h in holes:
            ax.add_patch(Polygon(h, color="#d9d6cf", zorder=0))
    for b in world.solids:
        alpha = 0.35 if b.kind == "bridge" else 1.0
        ax.add_patch(
            Polygon(b.footprint(), color=KIND_COLORS.get(b.kind, "#888"), alpha=alpha, zorder=1)
        )
    xs, ys = np.concatenate([states[:, 0], wp[:, 0]]), np.concatenate([states[:, 1], wp[:, 1]])
    # zoom on the run with a margin: 15 m in the canals, a few metres in the basin
    pad = float(np.clip(0.25 * max(np.ptp(xs), np.ptp(ys)), 2.0, 15.0))
    ax.set_xlim(xs.min() - pad, xs.max() + pad)
    ax.set_ylim(ys.min() - pad, ys.max() + pad)
    ax.plot(wp[:, 0], wp[:, 1], "o--", color="#2ca02c", label="waypoints", zorder=2)
    ax.plot(states[:, 0], states[:, 1], color="#d62728", lw=2, label="vessel", zorder=3)
    ax.set_aspect("equal")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.legend(loc="best")
    ax.set_title("Trajectory")
    traj = png_base64(fig)

    fig = Figure(figsize=(9, 8))
    axs = fig.subplots(3, 1, sharex=True)
    axs[0].plot(times, states[:, 3], label="u (surge)")
    axs[0].plot(times, states[:, 4], label="v (sway)")
    axs[0].plot(times, reference[:, 1], "--", label="u_d")
    axs[0].set_ylabel("[m/s]")
    axs[0].legend(loc="best")
    axs[1].plot(times, np.unwrap(states[:, 2]), label="ψ")
    axs[1].plot(times, np.unwrap(reference[:, 0]), "--", label="ψ_d")
    axs[1].set_ylabel("[rad]")
    axs[1].legend(loc="best")
    names = command_names(vessel.thrusters)
    for i, n in enumerate(names):
        if n.endswith(".force"):
            axs[2].plot(times, thrust[:, i], label=n[: -len(".force")])
    axs[2].set_ylabel("thrust [N]")
    axs[2].set_xlabel("time [s]")
    axs[2].legend(loc="best", ncol=4)
    signals = png_base64(fig)

    rows = "".join(
        f"<tr><td>{html.escape(k)}</td><td>{html.escape(json.dumps(v))}</td></tr>"
        for k, v in metrics.items()
    )
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;margin:2em}} td{{padding:2px 12px}}
tr:nth-child(odd){{background:#f3f3f3}}</style>
</head><body><h1>{html.escape(title)}</h1><table>{rows}</table>
<h2>Trajectory</h2><img src="data:image/png;base64,{traj}">
<h2>Signals</h2><img src="data:image/png;base64,{signals}"></body></html>"""
    with open(path, "w") as f:
        f.write(page)

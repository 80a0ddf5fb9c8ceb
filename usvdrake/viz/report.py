"""``report.html``: the plots a person looks at after a run — the trajectory on the world's map,
the cross-track error, speed, heading and thrust — as one offline HTML file with zoom and hover
(plotly, its script inlined once), and the run's metrics as a table of rounded numbers."""

import base64
import html
import io
import math

import numpy as np
import plotly.graph_objects as go
import plotly.io as pio
from plotly.subplots import make_subplots

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
LAND, WATER = "#d9d6cf", "#bcd7ef"


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


def format_value(v) -> str:
    """A metric as a person reads it: 4 significant digits, names without quotes, lists
    inline, nothing for None."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.4g}" if v != 0 else "0"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(format_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return ", ".join(f"{k}: {format_value(x)}" for k, x in v.items())
    return str(v)


def _ring(xy) -> tuple[list, list]:
    """A closed polygon as plotly x, y lists with a None after it (many rings in one trace)."""
    xy = np.asarray(xy, float)
    return [*xy[:, 0], xy[0, 0], None], [*xy[:, 1], xy[0, 1], None]


def _map_figure(world: World, states, times, waypoints) -> go.Figure:
    wp = np.asarray(waypoints, float).reshape(-1, 2)
    xs, ys = np.concatenate([states[:, 0], wp[:, 0]]), np.concatenate([states[:, 1], wp[:, 1]])
    # zoom on the run with a margin: 15 m in the canals, a few metres in the basin
    pad = float(np.clip(0.25 * max(np.ptp(xs), np.ptp(ys)), 2.0, 15.0))
    lo, hi = np.array([xs.min(), ys.min()]) - pad, np.array([xs.max(), ys.max()]) + pad
    fig = go.Figure()
    wx, wy, hx, hy = [], [], [], []
    for outer, holes in _water_patches(world.water):
        x, y = _ring(outer)
        wx += x
        wy += y
        for h in holes:
            x, y = _ring(h)
            hx += x
            hy += y
    fig.add_trace(
        go.Scatter(
            x=wx, y=wy, fill="toself", fillcolor=WATER, mode="none", name="water", hoverinfo="skip"
        )
    )
    if hx:
        fig.add_trace(
            go.Scatter(
                x=hx,
                y=hy,
                fill="toself",
                fillcolor=LAND,
                mode="none",
                showlegend=False,
                hoverinfo="skip",
            )
        )
    by_kind: dict[str, tuple[list, list]] = {}
    for b in world.solids:  # only what is in view: a city has thousands of buildings
        fp = b.footprint()
        if np.any(fp.max(axis=0) < lo) or np.any(fp.min(axis=0) > hi):
            continue
        x, y = _ring(fp)
        kx, ky = by_kind.setdefault(b.kind, ([], []))
        kx += x
        ky += y
    for kind, (x, y) in by_kind.items():
        fig.add_trace(
            go.Scatter(
                x=x,
                y=y,
                fill="toself",
                mode="none",
                name=kind,
                fillcolor=KIND_COLORS.get(kind, "#888"),
                opacity=0.35 if kind == "bridge" else 1.0,
                hoverinfo="name",
            )
        )
    fig.add_trace(
        go.Scatter(
            x=wp[:, 0],
            y=wp[:, 1],
            mode="lines+markers",
            name="waypoints",
            line={"color": "#2ca02c", "dash": "dash"},
        )
    )
    speed = np.hypot(states[:, 3], states[:, 4])
    fig.add_trace(
        go.Scatter(
            x=states[:, 0],
            y=states[:, 1],
            mode="lines",
            name="vessel",
            line={"color": "#d62728", "width": 3},
            customdata=np.column_stack([times, speed]),
            hovertemplate="t %{customdata[0]:.1f} s<br>x %{x:.2f} m, y %{y:.2f} m<br>"
            "speed %{customdata[1]:.2f} m/s<extra></extra>",
        )
    )
    fig.update_layout(
        plot_bgcolor=LAND,
        height=560,
        margin={"t": 30, "b": 40},
        xaxis={"title": "x east [m]", "range": [lo[0], hi[0]]},
        yaxis={
            "title": "y north [m]",
            "range": [lo[1], hi[1]],
            "scaleanchor": "x",
            "scaleratio": 1,
        },
    )
    return fig


def _cross_track_figure(times, reference) -> go.Figure:
    e = reference[:, 2]
    fig = go.Figure(
        go.Scatter(
            x=times,
            y=e,
            mode="lines",
            name="cross-track error",
            hovertemplate="t %{x:.1f} s: %{y:.3f} m<extra></extra>",
        )
    )
    rmse = float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")
    fig.add_hline(y=0.0, line={"color": "#999", "width": 1})
    fig.update_layout(
        height=280,
        margin={"t": 30, "b": 40},
        title=f"RMSE {rmse:.3f} m, max {np.max(np.abs(e)) if len(e) else 0:.3f} m",
        xaxis_title="time [s]",
        yaxis_title="cross-track error [m]",
    )
    return fig


def _signals_figure(times, states, reference, thrust, vessel) -> go.Figure:
    fig = make_subplots(rows=3, cols=1, shared_xaxes=True, vertical_spacing=0.04)
    lines = [
        (1, states[:, 3], "u (surge)", None),
        (1, states[:, 4], "v (sway)", None),
        (1, reference[:, 1], "u_d", "dash"),
        (2, np.unwrap(states[:, 2]), "ψ", None),
        (2, np.unwrap(reference[:, 0]), "ψ_d", "dash"),
    ]
    for i, n in enumerate(command_names(vessel.thrusters)):
        if n.endswith(".force"):
            lines.append((3, thrust[:, i], n[: -len(".force")], None))
    for row, y, name, dash in lines:
        fig.add_trace(
            go.Scatter(x=times, y=y, mode="lines", name=name, line={"dash": dash} if dash else {}),
            row=row,
            col=1,
        )
    fig.update_yaxes(title_text="[m/s]", row=1, col=1)
    fig.update_yaxes(title_text="heading [rad]", row=2, col=1)
    fig.update_yaxes(title_text="thrust [N]", row=3, col=1)
    fig.update_xaxes(title_text="time [s]", row=3, col=1)
    fig.update_layout(height=720, margin={"t": 20, "b": 40}, hovermode="x unified")
    return fig


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
    figures = [
        ("Trajectory", _map_figure(world, states, times, waypoints)),
        ("Cross-track error", _cross_track_figure(times, reference)),
        ("Speed, heading and thrust", _signals_figure(times, states, reference, thrust, vessel)),
    ]
    # plotly.js inlined once, in the first figure: the report stays one file that works offline
    body = "".join(
        f"<h2>{name}</h2>"
        + pio.to_html(fig, full_html=False, include_plotlyjs=(i == 0), config={"responsive": True})
        for i, (name, fig) in enumerate(figures)
    )
    rows = "".join(
        f"<tr><td>{html.escape(k)}</td><td>{html.escape(format_value(v))}</td></tr>"
        for k, v in metrics.items()
    )
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;margin:2em}} td{{padding:2px 12px}}
tr:nth-child(odd){{background:#f3f3f3}}</style>
</head><body><h1>{html.escape(title)}</h1><table>{rows}</table>
{body}</body></html>"""
    with open(path, "w") as f:
        f.write(page)

"""The figures of :func:`analyze_stability`: the closed-loop pole map (s-plane, z-plane and a
zoom near z = 1), Bode plots of each loop broken at a plant input with its margins, and slices
of the region of attraction with the sampled states, drawn on matplotlib Figures with the Agg
canvas (no pyplot)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from usvdrake.analysis.stability.linearisation import CHANNELS
from usvdrake.analysis.stability.loops import LinearLoop
from usvdrake.analysis.stability.roa import RegionOfAttraction


# --- plots ---------------------------------------------------------------------------------------
def _figure(w=10, h=4.5):
    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig


_MARKERS = ["x", "o", "s", "^", "d", "v"]


def _plot_poles(loops: dict, path: Path, title: str) -> Path:
    fig = _figure(15, 4.8)
    ax_s, ax_z, ax_zz = (fig.add_subplot(1, 3, k) for k in (1, 2, 3))
    zoom = []
    for i, (name, (c, s, _)) in enumerate(loops.items()):
        mk = _MARKERS[i % len(_MARKERS)]
        style = (
            {"marker": mk, "color": f"C{i}"}
            if mk == "x"
            else {
                "marker": mk,
                "facecolors": "none",
                "edgecolors": f"C{i}",
            }
        )
        if c is not None:
            ev = c.eigenvalues()
            ax_s.scatter(ev.real, ev.imag, label=name, **style)
        if s is not None:
            ev = s.eigenvalues()
            for ax in (ax_z, ax_zz):
                ax.scatter(ev.real, ev.imag, label=f"{name} (T = {s.dt:g} s)", **style)
            zoom += list(ev[np.abs(ev) > 0.5])
    th = np.linspace(0, 2 * np.pi, 2000)
    for ax in (ax_z, ax_zz):
        ax.plot(np.cos(th), np.sin(th), "k-", lw=0.8)
    ax_s.axvline(0.0, color="k", lw=0.8)
    if zoom:
        zoom = np.array(zoom)
        half = max(np.max(np.abs(zoom - 1.0)), 0.02) * 1.15
        ax_zz.set_xlim(1.0 - 2 * half, 1.0 + 0.2 * half)
        ax_zz.set_ylim(-1.1 * half, 1.1 * half)
    titles = ("s-plane (continuous)", "z-plane (sampled)", "z-plane near z = 1")
    for ax, t in zip((ax_s, ax_z, ax_zz), titles, strict=True):
        ax.set_title(t)
        ax.set_xlabel("Re")
        ax.set_ylabel("Im")
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    ax_z.set_aspect("equal")
    fig.suptitle(f"Closed-loop poles: {title}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _plot_bode(cont: LinearLoop | None, samp: LinearLoop | None, path: Path, name: str) -> Path:
    fig = _figure(10, 7)
    ax_m, ax_p = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    ref = cont if cont is not None else samp
    w_max = np.pi / samp.dt * 0.999 if samp is not None else 100.0
    w = np.logspace(-3, np.log10(w_max), 600)
    for i, ch in enumerate(ref.channels):
        for loop, style in ((cont, "-"), (samp, "--")):
            if loop is None:
                continue
            resp = loop.frequency_response(i, w)
            mag = 20 * np.log10(np.abs(resp))
            ph = np.degrees(np.unwrap(np.angle(resp)))
            ph -= 360.0 * np.ceil((ph[0] - 90.0) / 360.0)  # low-frequency phase in (−270°, 90°]
            m = loop.margins(i)
            kind = "cont." if loop is cont else f"T = {loop.dt:g} s"
            label = (
                f"{ch} {kind}: GM {_fmt_opt(m['gain_margin_db'])} dB, PM "
                f"{_fmt_opt(m['phase_margin_deg'])}°"
            )
            ax_m.semilogx(w, mag, style, color=f"C{i}", label=label)
            ax_p.semilogx(w, ph, style, color=f"C{i}")
            if m["gain_crossover_rad_s"] is not None:
                ax_p.plot(
                    m["gain_crossover_rad_s"], m["phase_margin_deg"] - 180.0, "o", color=f"C{i}"
                )
    ax_m.axhline(0.0, color="k", lw=0.8)
    ax_p.axhline(-180.0, color="k", lw=0.8)
    ax_m.set_ylabel("|L| [dB]")
    ax_p.set_ylabel("∠L [deg]")
    ax_p.set_xlabel("ω [rad/s]")
    ax_m.legend(fontsize=7)
    ax_m.grid(True, which="both", alpha=0.3)
    ax_p.grid(True, which="both", alpha=0.3)
    ax_m.set_title(f"Loop broken at the plant input: {name} (solid continuous, dashed sampled)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _fmt_opt(x):
    return "inf" if x is None else f"{x:.1f}"


def _plot_roa(data: dict, path: Path) -> Path:
    roa: RegionOfAttraction = data["roa"]
    check = data["check"]
    fig = _figure(14, 4.8)
    pinv = np.linalg.inv(roa.P)
    th = np.linspace(0, 2 * np.pi, 400)
    circle = np.vstack([np.cos(th), np.sin(th)])
    deg = np.degrees(1.0)
    pairs = [((0, 3), "e_x [m]", "u [m/s]", 1.0), ((1, 4), "e_y [m]", "v [m/s]", 1.0)]
    pairs.append(((2, 5), "ψ̃ [deg]", "r [deg/s]", deg))
    rng = np.random.default_rng(0)
    pick = rng.choice(len(check["z"]), size=min(2000, len(check["z"])), replace=False)
    zs, sat = check["z"][pick], check["saturated"][pick]
    for ch, ((i, j), xl, yl, sc) in enumerate(pairs):
        ax = fig.add_subplot(1, 3, ch + 1)
        idx = [i, j]
        own = sat[:, ch]
        ax.scatter(zs[~own, i] * sc, zs[~own, j] * sc, s=2, color="0.65", label="samples")
        ax.scatter(
            zs[own, i] * sc, zs[own, j] * sc, s=3, color="C3", label="samples, this τ saturated"
        )
        slice_m = roa.P[np.ix_(idx, idx)]
        shadow_m = np.linalg.inv(pinv[np.ix_(idx, idx)])
        same = np.allclose(slice_m, shadow_m, rtol=1e-9, atol=0.0)
        for rho, label, color in (
            (roa.rho, "V = ρ (box saturation)", "C0"),
            (roa.rho_unsaturated, "V = ρ unsaturated", "C2"),
        ):
            mats = [(slice_m, "slice" if not same else "slice = projection", "-")]
            if not same:
                mats.append((shadow_m, "projection", "--"))
            for mat, lab2, style in mats:
                ell = np.linalg.cholesky(mat)
                pts = np.linalg.solve(ell.T, np.sqrt(rho) * circle) * sc
                ax.plot(pts[0], pts[1], style, lw=1.6, color=color, label=f"{label}, {lab2}")
        kk = roa.K[ch, idx]
        xlim, ylim = ax.get_xlim(), ax.get_ylim()
        xs = np.linspace(xlim[0], xlim[1], 10) / sc
        if abs(kk[1]) > 0:
            for sgn in (1, -1):
                ys = (sgn * roa.tau_max[ch] - kk[0] * xs) / kk[1]
                ax.plot(
                    xs * sc, ys * sc, "k:", lw=0.9, label="|τ| = τ_max (slice)" if sgn > 0 else None
                )
        ax.set_xlim(xlim)
        ax.set_ylim(ylim)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.grid(True, alpha=0.3)
        ax.set_title(f"{CHANNELS[ch]}: τ_max = {roa.tau_max[ch]:.3g}")
        if ch == 0:
            ax.legend(fontsize=6, loc="upper right")
    fig.suptitle(
        f"Region of attraction, V = zᵀPz ≤ ρ = {roa.rho:.3g} (samples of the 6-D set projected; "
        f"{check['samples']} checked, max V̇ = {check['max_vdot']:.2e})"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path

"""Speed profiles over the limits, with the gradient profile under them (matplotlib, no display)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, Problem
from ..sim.result import Profile
from .report import atomic_write

COND_COLOURS = {"T": "#d62728", "K": "#1f77b4", "C": "#2ca02c", "B": "#7f7f7f"}


def plot_profiles(path: str | Path, profiles: list[tuple[str, Profile]], title: str) -> None:
    """Draw one or more speed profiles (label, one-plan Profile) against the speed limit, with the
    equivalent gradient underneath; ``.png`` or ``.svg`` by extension, written atomically."""
    path = Path(path)
    if path.suffix.lower() not in (".png", ".svg"):
        raise InputError(Problem(str(path), "--plot", "use a .png or .svg file name"))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..sim.result import CONDITIONS

    ref = profiles[0][1]
    s_km = ref.s_m / 1000.0
    fig, (ax, axg) = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.step(s_km[:-1], ref.limit_kmh, where="post", color="black", lw=1.2, label="speed limit")
    single = len(profiles) == 1
    for label, prof in profiles:
        v = prof.v_kmh[0]
        if single:  # colour the one profile by the condition applied in each cell
            cond = prof.condition[0]
            for code, name in enumerate(CONDITIONS):
                mask = cond == code
                if not mask.any():
                    continue
                seg = np.where(mask, v[1:], np.nan)
                ax.plot(s_km[1:], seg, color=COND_COLOURS[name], lw=2, label={"T": "traction", "K": "cruise", "C": "coast", "B": "brake"}[name])
            ax.plot(s_km, v, color="black", lw=0.4, alpha=0.5)
        else:
            ax.plot(s_km, v, lw=1.6, label=label)
    ax.set_ylabel("speed [km/h]")
    ax.set_ylim(0, max(float(ref.limit_kmh.max()), max(float(np.nanmax(p.v_kmh)) for _, p in profiles)) * 1.12)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", ncol=3, fontsize=8)
    axg.fill_between(s_km[:-1], ref.gradient_permille, step="post", color="#8c564b", alpha=0.5)
    axg.axhline(0, color="black", lw=0.6)
    axg.set_ylabel("equiv. gradient [‰]")
    axg.set_xlabel("position [km]")
    axg.grid(alpha=0.3)
    fig.tight_layout()
    fmt = path.suffix.lower().lstrip(".")
    try:
        atomic_write(path, lambda p: fig.savefig(p, format=fmt, dpi=130))
    finally:
        plt.close(fig)

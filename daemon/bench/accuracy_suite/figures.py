"""Figures of the accuracy benchmark, in the manner of the paper's figures 4-6 (matplotlib, PNG)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.bench.accuracy_suite.plan import LOSS_THRESHOLD
from flagtrack.daemon.bench.accuracy_suite.tables import PAPER_FAMILY

STYLE = {"paper": ("tab:red", "s"), "robust-classic": ("tab:blue", "^"), "robust": ("tab:green", "o")}


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _style(method: str) -> tuple[str, str]:
    return STYLE.get(method, ("tab:gray", "x"))


def _methods(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Methods in the order of the rows, ``robust`` first (drawn under the others)."""
    names = list(dict.fromkeys(r["method"] for r in rows))
    return sorted(names, key=lambda m: m != "robust")


def _log_bins(values: np.ndarray, n: int = 36) -> np.ndarray:
    """Logarithmic bins spanning the finite positive ``values``."""
    v = values[np.isfinite(values) & (values > 0)]
    if len(v) == 0:
        return np.logspace(-2, 2, n + 1)
    lo, hi = np.log10(v.min()) - 0.05, np.log10(v.max()) + 0.05
    return np.logspace(lo, max(hi, lo + 0.5), n + 1)


def _pct(values: Sequence[float]) -> np.ndarray:
    return 100.0 * np.asarray(values, dtype=np.float64)


def family_figure(rows: Sequence[dict[str, Any]], path: Path) -> None:
    """Fig. 4 (c-e): tip vs shape errors, travelling-wave index errors and I vs I_ref."""
    plt = _pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(11, 8.5))
    lo_d, hi_d = PAPER_FAMILY["delta_rms_over_l"]
    lo_e, hi_e = PAPER_FAMILY["max_eps_rms_over_l"]
    ax[0, 0].add_patch(
        plt.Rectangle(
            (100 * lo_d, 100 * lo_e),
            100 * (hi_d - lo_d),
            100 * (hi_e - lo_e),
            color="0.85",
            label="paper's range",
            zorder=0,
        )
    )
    bins = _log_bins(_pct([r["delta_rms_over_l"] for r in rows]))
    rel_bins = _log_bins(_pct([r["twi_rel_error"] for r in rows]))
    for method in _methods(rows):
        group = [r for r in rows if r["method"] == method]
        color, marker = _style(method)
        width = 2.5 if method == "robust" else 1.2  # drawn under the others: visible where they coincide
        d, e = _pct([r["delta_rms_over_l"] for r in group]), _pct([r["max_eps_rms_over_l"] for r in group])
        if method == "robust":
            sc = ax[0, 0].scatter(
                d,
                e,
                c=[r["wavelength_over_l"] for r in group],
                cmap="viridis",
                marker=marker,
                s=14,
                label=method,
                zorder=3,
            )
            fig.colorbar(sc, ax=ax[0, 0], label="λ/L (robust)")
        else:
            ax[0, 0].scatter(d, e, color=color, marker=marker, s=10, alpha=0.5, label=method, zorder=2)
        ax[0, 1].hist(d, bins=bins, histtype="step", color=color, lw=width, label=f"{method} δ_RMS/L")
        rel = _pct([r["twi_rel_error"] for r in group])
        ax[1, 0].hist(rel[np.isfinite(rel)], bins=rel_bins, histtype="step", color=color, lw=width, label=method)
        ax[1, 1].scatter(
            [r["twi_ref"] for r in group],
            [r["twi"] for r in group],
            color=color,
            marker=marker,
            s=10,
            alpha=0.6,
            label=method,
        )
    ax[0, 0].set(
        xscale="log", yscale="log", xlabel="δ_RMS / L (%)", ylabel="max ε_RMS / L (%)", title="(c) tip and shape errors"
    )
    ax[0, 0].legend(fontsize=8)
    ax[0, 1].axvspan(100 * lo_d, 100 * hi_d, color="0.85", label="paper's range")
    ax[0, 1].set(xscale="log", xlabel="δ_RMS / L (%)", ylabel="recordings", title="tip error histogram")
    ax[0, 1].legend(fontsize=8)
    for value, label in (
        (PAPER_FAMILY["twi_rel_error_median"], "paper median"),
        (PAPER_FAMILY["twi_rel_error_p95"], "paper 95 %"),
    ):
        ax[1, 0].axvline(100 * value, color="k", ls="--" if "median" in label else ":", label=label)
    ax[1, 0].set(
        xscale="log", xlabel="|I - I_ref| / I_ref (%)", ylabel="recordings", title="(d) travelling-wave index error"
    )
    ax[1, 0].legend(fontsize=8)
    top = max([1e-3] + [max(r["twi"], r["twi_ref"]) for r in rows if math.isfinite(r["twi"])]) * 1.05
    ax[1, 1].plot([0, top], [0, top], color="k", lw=0.8)
    ax[1, 1].set(xlabel="I_ref", ylabel="I", title="(e) travelling-wave index", xlim=(0, top), ylim=(0, top))
    ax[1, 1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _band(ax: Any, summary: Sequence[dict[str, Any]], method: str, x_key: str, y_key: str, label: str) -> None:
    entries = sorted((e for e in summary if e["method"] == method), key=lambda e: e[x_key])
    if not entries:
        return
    color, marker = _style(method)
    x = [e[x_key] for e in entries]
    ax.plot(x, _pct([e[f"{y_key}_median"] for e in entries]), color=color, marker=marker, label=f"{label} median")
    ax.plot(x, _pct([e[f"{y_key}_max"] for e in entries]), color=color, ls=":", label=f"{label} worst")


def defects_figure(leak: Sequence[dict[str, Any]], shot: Sequence[dict[str, Any]], path: Path) -> None:
    """Fig. 5: delta_RMS/L and t_loss versus leak rate; delta_RMS/L and N/N0 versus shot noise."""
    plt = _pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(11, 8.5))
    for method in _methods(list(leak) + list(shot)):
        _band(ax[0, 0], leak, method, "level", "delta_rms_over_l", method)
        _band(ax[1, 0], shot, method, "level", "delta_rms_over_l", method)
        color, marker = _style(method)
        entries = sorted((e for e in leak if e["method"] == method), key=lambda e: e["level"])
        lost = [(e["level"], e["t_loss_cycles_min"]) for e in entries if math.isfinite(e["t_loss_cycles_min"])]
        never = [(e["level"], e["evaluated_cycles_min"]) for e in entries if not math.isfinite(e["t_loss_cycles_min"])]
        if lost:
            ax[0, 1].plot(*zip(*lost), color=color, marker=marker, ls="", label=f"{method}: first loss")
        if never:
            ax[0, 1].plot(*zip(*never), color=color, marker="^", ls="", mfc="none", label=f"{method}: never lost (≥)")
    if shot:
        levels = sorted({e["level"] for e in shot})
        ratio = {lv: [e["n_over_n0_median"] for e in shot if e["level"] == lv][0] for lv in levels}
        ax[1, 1].plot(levels, [ratio[lv] for lv in levels], "ko-", label="ours (median over kinematics)")
        ax[1, 1].plot(levels, [1 + lv / 37 for lv in levels], "k--", label="paper: N/N0 = 2 at f_snr/f = 37")
    for axis, threshold, name in ((ax[0, 0], 1.2, "paper: f_lr/f = 1.2"), (ax[1, 0], 35.0, "paper: f_snr/f = 35")):
        axis.axhline(1.0, color="k", lw=0.8, ls="--", label="1 % of L")
        axis.axvline(threshold, color="0.5", lw=0.8, label=name)
        axis.axvline(2 * threshold, color="0.5", lw=0.8, ls="-.", label="twice that")
        axis.set(yscale="log", ylabel="δ_RMS / L (%)")
        axis.legend(fontsize=7)
    ax[0, 0].set(xlabel="f_lr / f (leak rate over flapping frequency; v2e leak)", title="(a) leak")
    ax[0, 1].set(
        yscale="log",
        xlabel="f_lr / f",
        ylabel=f"t_loss (cycles; δ/L > {LOSS_THRESHOLD:g})",
        title="(b) first loss of tracking",
    )
    ax[0, 1].legend(fontsize=7)
    ax[1, 0].set(xlabel="paper-equivalent f_snr / f (= 37 (N/N0 - 1))", title="(f) shot noise")
    ax[1, 1].set(xlabel="paper-equivalent f_snr / f", ylabel="N_evs / N_evs,0", title="events with noise")
    ax[1, 1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def params_figure(joints: Sequence[dict[str, Any]], tau: Sequence[dict[str, Any]], path: Path) -> None:
    """Fig. 6: delta_RMS/L versus N_j and tau/T, clean (solid) and noisy (f_snr/f = 20, dashed)."""
    plt = _pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    for axis, summary, key in ((ax[0], joints, "joints"), (ax[1], tau, "tau_over_t")):
        for method in _methods(summary):
            color, marker = _style(method)
            for condition, ls in (("clean", "-"), ("shot 20", "--")):
                entries = sorted(
                    (e for e in summary if e["method"] == method and e["condition"] == condition), key=lambda e: e[key]
                )
                if entries:
                    axis.plot(
                        [e[key] for e in entries],
                        _pct([e["delta_rms_over_l_median"] for e in entries]),
                        color=color,
                        marker=marker,
                        ls=ls,
                        label=f"{method}, {'clean' if condition == 'clean' else 'noisy'}",
                    )
        axis.set(yscale="log", ylabel="δ_RMS / L (%), median over kinematics")
        axis.legend(fontsize=7)
    ax[0].set(xlabel="N_j", title="(a) number of joints (τ/T = 5e-3)")
    ax[1].set(xscale="log", xlabel="τ / T", title="(b) update interval (N_j = 10)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""Figures: disparity and confidence maps as colour maps with their scales, the calibration
(reliability and sparsification) plot, and the Fig 6 sweep plots."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, never a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["disparity_gray", "save_disparity_figure", "save_confidence_figure", "save_calibration_figure",
           "save_sweep_figure", "save_dataset_sweep_figure"]

DISPARITY_CMAP = "turbo"
CONFIDENCE_CMAP = "viridis"
NO_MATCH_COLOUR = "white"  # no match (and unknown ground truth): outside every colour map used here


def disparity_gray(disp: np.ndarray, dmax: int) -> np.ndarray:
    """Fig 7 convention as uint8: black = no match (< 0), gray proportional to d, white = Dmax.

    Non-finite values (unknown ground truth) are black too; d > Dmax saturates to white.
    """
    d = np.asarray(disp, dtype=np.float64)
    valid = np.isfinite(d) & (d >= 0)
    gray = np.zeros(d.shape, dtype=np.uint8)
    scale = 255.0 / max(dmax, 1)
    gray[valid] = np.round(np.clip(d[valid], 0, dmax) * scale).astype(np.uint8)
    return gray


def _grid(n: int, shape: tuple[int, ...], extra_width: float = 0.0):  # noqa: ANN202
    cols = 2 if n == 4 else min(n, 3)
    rows = -(-n // cols)
    h, w = shape[:2]
    size = (4.5 * cols + extra_width, (4.5 * h / w + 0.5) * rows + 0.5)
    return plt.subplots(rows, cols, figsize=size, squeeze=False, layout="constrained")


def _masked(values: np.ndarray) -> np.ma.MaskedArray:
    v = np.asarray(values, dtype=np.float64)
    return np.ma.masked_invalid(np.where(np.isfinite(v) & (v >= 0), v, np.nan))


def _no_match_legend(fig, label: str) -> None:  # noqa: ANN001
    from matplotlib.patches import Patch

    fig.legend(handles=[Patch(facecolor=NO_MATCH_COLOUR, edgecolor="black", label=label)],
               loc="lower right", fontsize=8, frameon=False)


def save_disparity_figure(
    path: str | Path,
    left: np.ndarray,
    panels: Sequence[tuple[str, np.ndarray] | tuple[str, np.ndarray, np.ndarray]],
    dmax: int,
) -> None:
    """The left image, then each (title, disparity map[, marked]) panel, coloured on one scale 0..Dmax with
    its colour bar; no match (< 0) and unknown (non-finite) in :data:`NO_MATCH_COLOUR`; a panel's
    ``marked`` pixels (bool, e.g. those an occlusion fill gave a value) lightened by a white veil."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    fig, axes = _grid(1 + len(panels), left.shape, extra_width=1.0)
    cmap = plt.get_cmap(DISPARITY_CMAP).with_extremes(bad=NO_MATCH_COLOUR)
    norm = Normalize(0, max(dmax, 1))
    axes.flat[0].imshow(left, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    axes.flat[0].set_title("Left image", fontsize=9)
    for ax, (title, disp, *marked) in zip(list(axes.flat)[1:], panels, strict=False):
        ax.imshow(_masked(disp), cmap=cmap, norm=norm, interpolation="nearest")
        if marked:
            veil = np.zeros((*np.shape(disp), 4))
            veil[np.asarray(marked[0], bool)] = (1.0, 1.0, 1.0, 0.55)
            ax.imshow(veil, interpolation="nearest")
        ax.set_title(title, fontsize=9)
    for ax in axes.flat:
        ax.set_axis_off()
    fig.colorbar(ScalarMappable(norm, cmap), ax=axes, shrink=0.8, label="disparity (pixels)")
    _no_match_legend(fig, "no match / unknown")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def save_confidence_figure(path: str | Path, left: np.ndarray, maps: object, disp: np.ndarray,
                           title: str) -> None:
    """The left image and a method's per-pixel confidence, entropy and no-match mass
    (:class:`~.confidence.ConfidenceMaps`), each with its colour bar; the confidence of a pixel
    without a MAP disparity (``disp`` < 0) in :data:`NO_MATCH_COLOUR`."""
    fig, axes = _grid(4, left.shape, extra_width=1.5)
    axes[0, 0].imshow(left, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    axes[0, 0].set_title("Left image", fontsize=9)
    conf = np.where(np.asarray(disp) >= 0, maps.confidence, np.nan)  # type: ignore[attr-defined]
    for ax, (name, values, cmap, hi, label) in zip(list(axes.flat)[1:], [
        (title, conf, CONFIDENCE_CMAP, 1.0, "confidence"),
        ("Entropy of the distribution", maps.entropy, "magma", None, "bits"),  # type: ignore[attr-defined]
        ("No-match mass", maps.nomatch_mass, "cividis", 1.0, "probability"),  # type: ignore[attr-defined]
    ], strict=True):
        cm = plt.get_cmap(cmap).with_extremes(bad=NO_MATCH_COLOUR)
        vmax = hi if hi is not None else max(float(np.nanmax(values)) if np.isfinite(values).any() else 1.0,
                                             1e-6)
        im = ax.imshow(np.ma.masked_invalid(values), cmap=cm, vmin=0, vmax=vmax, interpolation="nearest")
        ax.set_title(name, fontsize=9)
        fig.colorbar(im, ax=ax, shrink=0.8, label=label)
    for ax in axes.flat:
        ax.set_axis_off()
    _no_match_legend(fig, "no match")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def save_calibration_figure(path: str | Path, report: dict[str, object]) -> None:
    """(a) The reliability diagram (observed rate of |d - gt| <= t against the mean confidence per
    bin) and (b) the sparsification curves (bad-2 of the kept pixels against the fraction removed,
    least confident first) of the report's ``confidence`` entry (:func:`~.metrics.confidence_report`)."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5), layout="constrained")
    t = report["t"]
    a.plot([0, 1], [0, 1], color="gray", linestyle=":", label="perfectly calibrated")
    fractions = np.asarray(report["fractions"], dtype=np.float64)
    styles = {"machine": ("o-", "C0", "machine"), "reference": ("s--", "C1", "float64 reference")}
    def num(v: object, fmt: str) -> str:  # a figure of no pixel is null in the report
        return "n/a" if v is None else format(v, fmt)

    def curve(values: object) -> np.ndarray:
        return np.asarray(values, dtype=np.float64)  # null points (no pixel) are NaN: not drawn

    for key, (style, colour, name) in styles.items():
        figs = report.get(key)
        if not isinstance(figs, dict):
            continue
        table = [r for r in figs["reliability"] if r["count"]]
        a.plot([r["predicted"] for r in table], [r["observed"] for r in table], style, color=colour,
               label=f"{name} (ECE {num(figs['ece'], '.3f')})")
        b.plot(fractions, curve(figs["curve"]), style, color=colour,
               label=f"{name} (AUC {num(figs['auc'], '.4f')})")
        if key == "machine":
            b.plot(fractions, curve(figs["curve_perfect"]), ":", color=colour,
                   label=f"machine, perfect order (AUC {num(figs['auc_perfect'], '.4f')})")
            if figs["auc_random"] is not None:
                b.axhline(figs["auc_random"], color=colour, linestyle="-.", alpha=0.6,
                          label=f"machine, random order (AUC {figs['auc_random']:.4f})")
    lr = report.get("sgbm_lr")
    if isinstance(lr, dict):
        b.plot(fractions, curve(lr["curve"]), "^-", color="C2", alpha=0.8,
               label=f"SGBM, left-right check (AUC {num(lr['auc'], '.4f')})")
    a.set_xlim(0, 1)
    a.set_ylim(0, 1.02)
    a.set_xlabel("confidence (mean per bin)")
    a.set_ylabel(f"observed rate of |d - gt| <= {t}")
    a.set_title(f"(a) reliability, {report['bins']} bins", fontsize=10)
    a.legend(fontsize=8)
    a.grid(True, alpha=0.3)
    b.set_xlabel("fraction of pixels removed (least confident first)")
    b.set_ylabel(f"bad-{report['sparsification_bad']} of the kept pixels")
    b.set_title("(b) sparsification", fontsize=10)
    b.set_ylim(bottom=0)
    b.legend(fontsize=7)
    b.grid(True, alpha=0.3)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def save_sweep_figure(path: str | Path, sweep: Sequence[dict[str, object]]) -> None:
    """Fig 6: (a) RMS error, no-match F1 and MAP agreement vs counter max; (b) cycles/pixel (mean,
    median, 10-90 % band). Points with several random sources (key ``rng``) get one colour each; a point
    without a counter max (a log machine's) is a dotted level across."""
    from matplotlib.lines import Line2D

    kinds = list(dict.fromkeys(str(s.get("rng", "")) for s in sweep))
    several = len(kinds) > 1
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    metrics = [("rms_error", "o-", "RMS error (matched pixels)", 1.0),
               ("nomatch_f1", "s-", "F1 (no-match detection)", 0.8),
               ("map_agreement", "^--", "MAP agreement", 0.6)]
    for i, kind in enumerate(kinds):
        pts = [s for s in sweep if str(s.get("rng", "")) == kind]
        colour = colours[i % len(colours)]
        flat = [s for s in pts if s.get("counter_max") is None]  # a machine without counters: a level
        for s, (key, _style, _, alpha) in itertools.product(flat, metrics):
            if s.get(key) is not None:
                a.axhline(float(s[key]), color=colour, linestyle=":", alpha=alpha)  # type: ignore[arg-type]
        for s in flat:
            b.axhline(float(s["cycles_per_pixel_mean"]), color=colour, linestyle=":")  # type: ignore[arg-type]
        pts = [s for s in pts if s.get("counter_max") is not None]
        cm = np.array([float(s["counter_max"]) for s in pts])  # type: ignore[arg-type]

        def col(key: str, pts: list[dict[str, object]] = pts) -> np.ndarray:
            return np.array([np.nan if s.get(key) is None else float(s[key]) for s in pts])  # type: ignore[arg-type]

        for key, style, label, alpha in metrics:
            a.plot(cm, col(key), style, color=colour, alpha=alpha, label=None if several else label)
        # The per-pixel distribution is heavy-tailed, so mean +- std would dip below zero: show the
        # mean, the median and the 10-90 % band instead (std over pixels is in the JSON).
        b.plot(cm, col("cycles_per_pixel_mean"), "o-", color=colour, label=None if several else "mean")
        b.plot(cm, col("cycles_per_pixel_median"), "s--", color=colour, alpha=0.8,
               label=None if several else "median")
        b.fill_between(cm, col("cycles_per_pixel_p10"), col("cycles_per_pixel_p90"), color=colour,
                       alpha=0.1 if several else 0.2, label=None if several else "10-90 % of pixels")
    if several:  # colours name the sources, markers the quantities
        sources = [Line2D([], [], color=colours[i % len(colours)], label=k) for i, k in enumerate(kinds)]
        a.legend(handles=sources + [Line2D([], [], color="gray", marker=st[0], linestyle=st[1:], label=lb)
                                    for _, st, lb, _ in metrics], fontsize=7, ncol=2)
        b.legend(handles=sources + [Line2D([], [], color="gray", marker="o", label="mean"),
                                    Line2D([], [], color="gray", marker="s", linestyle="--", label="median")],
                 fontsize=7, title="10-90 % of pixels shaded", title_fontsize=7)
    else:
        a.legend(fontsize=8)
        b.legend(fontsize=8)
    a.set_xscale("log", base=2)
    a.set_xlabel("counter max")
    a.set_ylim(0, 1.02)
    a.grid(True, alpha=0.3)
    a.set_title("(a) accuracy vs the float64 reference")
    b.set_xlabel("counter max")
    b.set_ylabel("cycles per pixel")
    b.grid(True, alpha=0.3)
    b.set_title("(b) run time per pixel")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _series_label(point: dict[str, object], varying: Sequence[str]) -> str:
    grid = point.get("grid") or {}
    return " ".join(f"{grid.get(a)}" if a in ("model", "rng") else f"{a}={grid.get(a)}"  # type: ignore[union-attr]
                    for a in varying) or str(point.get("rng", ""))


def save_dataset_sweep_figure(path: str | Path, points: Sequence[dict[str, object]]) -> None:
    """A sweep over a dataset: (a) accuracy (RMS error, no-match F1, MAP agreement and, with ground
    truth, the machine's bad-2 with no match counted bad) and (b) cycles per pixel against counter max,
    each the mean over the pairs with a band of +- one std over the pairs. One colour per combination
    of the other grid axes (model, source, word bits, ...)."""
    from matplotlib.lines import Line2D

    axes_values: dict[str, list[object]] = {}
    for p in points:
        for k, v in (p.get("grid") or {}).items():  # type: ignore[union-attr]
            axes_values.setdefault(k, [])
            if v not in axes_values[k]:
                axes_values[k].append(v)
    varying = [k for k, v in axes_values.items() if k != "counter_max" and len(v) > 1]
    labels = list(dict.fromkeys(_series_label(p, varying) for p in points))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    metrics = [("rms_error", "o-", "RMS error"), ("nomatch_f1", "s-", "no-match F1"),
               ("map_agreement", "^--", "MAP agreement"), ("machine_bad2_nomatch_bad", "D:", "bad-2 (vs gt)")]
    metrics = [m for m in metrics if any(p.get(m[0]) is not None for p in points)]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
    n_pairs = max(int(p.get("pairs") or 0) for p in points) if points else 0  # type: ignore[call-overload]

    def col(pts: list[dict[str, object]], key: str, spread: bool = False) -> np.ndarray:
        src = [(p.get("std") or {}) if spread else p for p in pts]
        return np.array([np.nan if s.get(key) is None else float(s[key])  # type: ignore[union-attr,arg-type]
                         for s in src])

    for i, label in enumerate(labels):
        pts = sorted((p for p in points if _series_label(p, varying) == label),
                     key=lambda p: float(p["counter_max"]))  # type: ignore[arg-type]
        cm = np.array([float(p["counter_max"]) for p in pts])  # type: ignore[arg-type]
        colour = colours[i % len(colours)]
        for key, style, _ in metrics:
            m, s = col(pts, key), col(pts, key, spread=True)
            a.plot(cm, m, style, color=colour)
            a.fill_between(cm, m - s, m + s, color=colour, alpha=0.12)
        m, s = col(pts, "cycles_per_pixel_mean"), col(pts, "cycles_per_pixel_mean", spread=True)
        b.plot(cm, m, "o-", color=colour, label=label)
        b.fill_between(cm, m - s, m + s, color=colour, alpha=0.15)
    handles = [Line2D([], [], color="gray", marker=st[0], linestyle=st[1:], label=lb)
               for _, st, lb in metrics]
    if len(labels) > 1:
        handles = [Line2D([], [], color=colours[i % len(colours)], label=lb)
                   for i, lb in enumerate(labels)] + handles
    a.legend(handles=handles, fontsize=7, ncol=2)
    b.legend(fontsize=7, title="mean over pairs, +- 1 std shaded", title_fontsize=7)
    for ax in (a, b):
        ax.set_xscale("log", base=2)
        ax.set_xlabel("counter max")
        ax.grid(True, alpha=0.3)
    a.set_ylim(0, 1.02)
    a.set_title(f"(a) accuracy, mean +- std over {n_pairs} pairs")
    b.set_ylabel("cycles per pixel (pair mean)")
    b.set_title("(b) run time per pixel")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

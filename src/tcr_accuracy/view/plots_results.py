"""Plots of a campaign's results drawn from their JSON (matplotlib, Agg): the calibration report's figures.

``tcr-accuracy report`` has only the JSON results, not the runs, so its plots come from them:
a diagnosis' ladder (held-out error after each step) and its families' shares, an ISO 9283
test's per-pose AP_P and RP_l (as measured and predicted after compensation, per test
condition), a comparison's changes in standard errors. The limits of the campaign file are drawn
where a figure answers to one. ``iso9283 evaluate --out`` and ``compare --out`` draw theirs with
the same functions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..results.kinds import kind_of
from .plots_common import PlotFile, figure, legend_beside, save_figure, shared_legend
from .plots_diagnose import plot_ladder
from .result_tables import iso_condition_label


def write_result_plots(documents, folder: Path, limits_mm: dict | None = None) -> list:
    """Every plot of the JSON results ``documents`` ((source, dict), ...), for files in ``folder``.

    Returns
    -------
    list of (PlotFile, str)
        Each plot (:class:`~tcr_accuracy.view.plots_common.PlotFile`, meant for a file in ``folder``;
        nothing is written) with its caption, in the order of the documents.
    """
    limits_mm = limits_mm or {}
    folder = Path(folder)
    out = []
    for k, (source, doc) in enumerate(documents, start=1):
        kind = kind_of(doc, source)
        if kind == "diagnosis":
            steps = doc["steps"]
            out.append((plot_ladder([s["effect"] for s in steps], [s["heldout_rms_mm"] for s in steps],
                                    [s["heldout_mean_mm"] for s in steps], doc["noise_floor_mm"],
                                    folder / f"ladder-{k}.png", limits_mm.get("rms")),
                        f"How far the gap shrinks ({source}): held-out RMS and mean after each step, the noise "
                        "floor" + (" and the limit on the RMS" if "rms" in limits_mm else "")))
            if doc.get("families"):
                out.append((plot_families(doc["families"], folder / f"families-{k}.png"),
                            f"Share of each family of effects in the gap ({source}), with its 95 % interval"))
        elif kind == "iso9283":
            out.append((plot_iso_poses(doc, folder / f"iso-{k}.png", limits_mm),
                        f"ISO 9283 pose accuracy AP_P and repeatability RP_l per pose ({source})"
                        + (", as measured and predicted after compensation" if doc.get("compensated") else "")
                        + (", against the limits" if {"ap", "rp"} & set(limits_mm) else "")))
        elif kind == "comparison":
            out.append((plot_changes(doc, folder / f"changes-{k}.png"),
                        f"Change of each robot parameter between the campaigns in standard errors ({source})"))
    return out


def plot_families(families, path: Path) -> PlotFile:
    """Each family's share of the gap [mm] (how much the held-out RMS rises without it) with its
    95 % interval, the largest on top."""
    fig, axes = figure(1, 1, size=(7, 1.3 + 0.45 * len(families)))
    ax = axes[0, 0]
    y = np.arange(len(families))
    share = np.array([f["share_mm"] for f in families])
    low = np.array([f["interval_mm"][0] for f in families])
    high = np.array([f["interval_mm"][1] for f in families])
    ax.barh(y, share, 0.6, color="C0")
    ax.errorbar(share, y, xerr=[np.clip(share - low, 0, None), np.clip(high - share, 0, None)], fmt="none",
                ecolor="k", capsize=3, lw=1)
    ax.set_yticks(y, [f"{f['family']} ({', '.join(f['effects'])})" for f in families])
    ax.invert_yaxis()
    ax.set_xlabel("rise of the held-out RMS without the family [mm]")
    ax.set_title("Which family of effects causes the gap")
    return save_figure(fig, path)


def plot_iso_poses(iso, path: Path, limits_mm: dict | None = None) -> PlotFile:
    """Per pose: AP_P as measured, AP_P predicted after compensation (when the result has it) and
    RP_l [mm]; one panel per test condition; the limits on AP and RP as lines."""
    limits_mm = limits_mm or {}
    blocks = list(iso.get("conditions") or [iso])
    cols = min(2, len(blocks))
    rows = -(-len(blocks) // cols)
    fig, axes = figure(rows, cols, size=(5.2 * cols, 2.9 * rows + 0.7), sharey=True)
    for i in range(rows * cols):
        ax = axes[i // cols][i % cols]
        if i >= len(blocks):
            ax.axis("off")
            continue
        block = blocks[i]
        poses = [p.get("pose") or f"P{p['pose_id']}" for p in block["poses"]]
        x = np.arange(len(poses))
        series = [("AP_P as measured", [p["ap_mm"] for p in block["poses"]], "C0")]
        if block.get("compensated"):
            series.append(("AP_P predicted after compensation", [p["ap_mm"] for p in block["compensated"]["poses"]],
                           "C2"))
        series.append(("RP_l", [np.nan if p["rp_mm"] is None else p["rp_mm"] for p in block["poses"]], "C1"))
        width = 0.8 / len(series)
        for k, (label, values, colour) in enumerate(series):
            ax.bar(x + (k - (len(series) - 1) / 2) * width, values, width, label=label, color=colour)
        for key, colour, label in (("ap", "C0", "limit on AP_P"), ("rp", "C1", "limit on RP_l")):
            if key in limits_mm:
                ax.axhline(limits_mm[key], color=colour, ls="--", lw=1.2, label=f"{label}, {limits_mm[key]:g} mm")
        ax.set_xticks(x, poses)
        ax.set_title(iso_condition_label(block) or "pose test", fontsize=9)
        if i % cols == 0:
            ax.set_ylabel("[mm]")
    handles, labels = axes[0][0].get_legend_handles_labels()
    if len(blocks) == 1:
        legend_beside(axes[0][0])
    else:
        shared_legend(fig, axes, handles, labels)
    fig.suptitle(f"ISO 9283 pose test {iso.get('measurements', '')}")
    return save_figure(fig, path)


def plot_changes(cmp, path: Path) -> PlotFile:
    """Each robot parameter's change between the campaigns in standard errors (z), the threshold
    of significance as lines; the significant ones in red."""
    changes = [c for c in cmp["changes"] if c.get("z") is not None]
    changes.sort(key=lambda c: -abs(c["z"]))
    fig, axes = figure(1, 1, size=(7, 1.3 + 0.24 * max(len(changes), 1)))
    ax = axes[0, 0]
    y = np.arange(len(changes))
    z = np.array([c["z"] * np.sign(c["change"]) if c["change"] else 0.0 for c in changes])
    ax.barh(y, z, 0.7, color=["C3" if c.get("significant") else "0.6" for c in changes])
    threshold = cmp["z_threshold"]
    for sign in (-1, 1):
        ax.axvline(sign * threshold, color="k", ls="--", lw=1)
    ax.set_yticks(y, [c["parameter"] for c in changes], fontsize=7.5)
    ax.invert_yaxis()
    ax.set_xlabel(f"change / its standard error (signed; beyond +-{threshold:g}: significant, red)")
    ax.set_title(f"What changed since {cmp['old']}")
    return save_figure(fig, path)

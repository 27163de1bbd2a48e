"""Run records → figures (PNG and PDF, matplotlib): what accuracy costs in time and bytes.

Plot kinds (each `plot_<kind>(records, out_dir) -> [paths]`, nothing written where the records hold
no data for it; failed records are left out of every plot, the tables flag them):
  fit_curves   accuracy (probe chamfer L2) against fit time, one line per learned run, log-log, one
               panel per shape: the log-spaced probes each run records during its fit
  pareto       chamfer L2 against warm render time, fit time and storage (log axes), the
               non-dominated points joined (empty reconstructions drawn as crosses and never on the
               front), one row of panels per shape
  sampling     chamfer L2 against the number of training labels, one line per strategy (log-log)
  render_time  cold and warm render time per model and image size (bars, log axis; runs of the same
               model and size are averaged)
  frames_by_shape  warm frame time per shape (groups) and model (bars), log axis, the mean over seeds
               with its std; a shape's face count under its name
  ablation     chamfer L2 against each surface-sampling density (s_fc, s_dr, s_p), the others at
               their base (lowest) level: one line per factor
Which kinds an experiment gets: PLOTS_BY_EXPERIMENT (by the runs' experiment file, +experiment=NAME), else
DEFAULT_PLOTS; `python -m ddfbench.report --plots` chooses explicitly.
Accuracy is the record's chamfer L2 (squared, raw, not ×10³); seeds are averaged (error bars: std).
"""

from __future__ import annotations

import math
import os
from collections import defaultdict
from typing import Any, Callable, Iterable

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

from ddfbench.evaluate.metric_registry import by_name as registry_metrics  # noqa: E402
from ddfbench.report import convergence  # noqa: E402
from ddfbench.report.records import SURFACE_FACTORS, as_float, chamfer_l2, no_result, ok_records, shape_name  # noqa: E402
from ddfbench.report.stats import summarize_values  # noqa: E402
from ddfbench.report.tables import override_labels  # noqa: E402

PLOTS_BY_EXPERIMENT: dict[str, tuple[str, ...]] = {
    "ablation": ("ablation", "fit_curves"),
    "sampling": ("sampling", "fit_curves"),
    "representations": ("fit_curves", "pareto"),
    "storage": ("pareto", "fit_curves"),
    "render_time": ("render_time",),
    "pareto": ("pareto", "fit_curves"),
    "smoke": ("fit_curves", "pareto", "sampling", "render_time", "ablation"),
    "convergence": ("convergence", "fit_curves"),
    "paper_ddf": ("convergence", "fit_curves"),
    "gan_epochs": ("convergence", "fit_curves"),
    "render_matched": ("render_time",),
    "render_shapes": ("frames_by_shape", "pareto"),
    "tune": ("fit_curves",),  # plus reports/tune/tune.png by ddfbench.report.tune
    "shape_suite": ("fit_curves",),  # plus by_axis.png by ddfbench.report.shape_suite
    "tune_finalists": ("fit_curves",),
    "grid_encodings": ("fit_curves", "pareto"),
}
DEFAULT_PLOTS = ("fit_curves", "pareto")
COST_AXES = (("render_warm_s", "warm render time (s)"), ("fit_s", "fit time (s)"), ("storage_bytes", "storage (bytes)"))
PENALTY_CHAMFER_L2 = registry_metrics()["chamfer_l2"].penalty  # what an empty reconstruction scores


def pareto_front(x: Iterable[float], y: Iterable[float]) -> np.ndarray:
    """Indices of the points no other point dominates (lower-or-equal x and y, one strictly lower),
    ordered by increasing x. Points with a non-finite coordinate are never on the front.
    x, y: (N,) costs and errors, both to minimise."""
    x, y = np.asarray(list(x), dtype=float), np.asarray(list(y), dtype=float)
    finite = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    order = finite[np.lexsort((y[finite], x[finite]))]  # by x, then y
    front, best_y = [], math.inf
    for i in order:
        if y[i] < best_y:
            front.append(i)
            best_y = y[i]
    return np.array(front, dtype=int)


def _config_id(rec: dict[str, Any]) -> str:
    """The record's configuration, seeds pooled: its overrides minus seed=."""
    kept = [o for o in rec.get("overrides") or [] if not o.lstrip("+").startswith("seed=")]
    return " ".join(sorted(kept)) + f" | {rec.get('model')} {shape_name(rec)}"


def _labeller(records: list[dict[str, Any]]) -> Callable[[dict[str, Any]], str]:
    """rec -> "model key=value ..." with only the overrides whose value differs between the records."""
    labels = {id(r): override_labels(r.get("overrides") or []) for r in records}
    keys: list[str] = []
    for lab in labels.values():
        keys += [k for k in lab if k not in keys and k not in ("model", "shape")]
    varying = [k for k in keys if len({lab.get(k) for lab in labels.values()}) > 1]

    def label(rec: dict[str, Any]) -> str:
        lab = labels.get(id(rec)) or override_labels(rec.get("overrides") or [])
        return " ".join([str(rec.get("model"))] + [f"{k.split('/')[-1]}={lab[k]}" for k in varying if k in lab])

    return label


def _colors(names: Iterable[str]) -> dict[str, Any]:
    cmap = plt.get_cmap("tab10")
    return {n: cmap(i % 10) for i, n in enumerate(sorted(set(names)))}


def _save(fig: Any, out_dir: str, name: str) -> list[str]:
    os.makedirs(out_dir, exist_ok=True)
    paths = [os.path.join(out_dir, f"{name}.{ext}") for ext in ("png", "pdf")]
    fig.tight_layout()
    for p in paths:  # no creation date in the PDF: a rebuild from the same rows gives the same bytes
        fig.savefig(p, dpi=150, metadata={"CreationDate": None} if p.endswith(".pdf") else None)
    plt.close(fig)
    return paths


def _floor_line(ax: Any, floor: float) -> None:
    if math.isfinite(floor) and floor > 0:
        ax.axhline(floor, color="0.5", ls=":", lw=1, label="noise floor")


def _mean_std(values: list[float]) -> tuple[float, float]:
    """Mean and std of the finite values, for a point and its error bar (std 0 for one value, NaN for none)."""
    s = summarize_values(values)
    return s.mean, (s.std if s.n > 1 else 0.0 if s.n == 1 else math.nan)


def plot_fit_curves(records: list[dict[str, Any]], out_dir: str) -> list[str]:
    """Probe chamfer L2 against fit seconds per learned run (runs with at least two finite probes).
    Colour: the model, or the run's sweep label where all runs share one model. Probes of an empty
    reconstruction (the penalty value) are drawn as crosses."""
    runs = []
    for r in ok_records(records):
        pts = [(as_float(p.get("seconds")), as_float(p.get("chamfer_l2"))) for p in (r.get("fit") or {}).get("probes") or []]
        pts = [(s, c) for s, c in pts if math.isfinite(s) and math.isfinite(c) and s > 0 and c > 0]
        if len(pts) >= 2:
            runs.append((r, pts))
    if not runs:
        return []
    shapes = sorted({shape_name(r) for r, _ in runs})
    by_model = len({r.get("model") for r, _ in runs}) > 1
    name = (lambda r: str(r.get("model"))) if by_model else _labeller([r for r, _ in runs])
    colors = _colors(name(r) for r, _ in runs)
    fig, axes = plt.subplots(1, len(shapes), figsize=(5.5 * len(shapes), 4.2), squeeze=False)
    for ax, shape in zip(axes[0], shapes):
        labelled = set()
        for r, pts in runs:
            if shape_name(r) != shape:
                continue
            s, c = np.array(pts).T
            key = name(r)
            ax.plot(s, c, "-", lw=1, color=colors[key], alpha=0.8, label=key if key not in labelled else None)
            empty = np.isclose(c, PENALTY_CHAMFER_L2)
            ax.plot(s[~empty], c[~empty], "o", ms=3, color=colors[key])
            ax.plot(s[empty], c[empty], "x", ms=5, color=colors[key])
            labelled.add(key)
        _floor_line(ax, convergence.floor(records, shape))
        ax.set(xscale="log", yscale="log", xlabel="fit time (s)", ylabel="chamfer L2 (probe; × = empty mesh, penalty)",
               title=shape)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    return _save(fig, out_dir, "fit_curves")


def _config_points(records: list[dict[str, Any]], cost: str) -> list[dict[str, Any]]:
    """Per configuration (seeds pooled): model, shape, mean cost x, mean chamfer y, empty (a run's reconstruction
    was empty or off the shape: its mean is no method result, drawn as x and kept off the front, as the tables
    leave it unranked)."""
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in ok_records(records):
        groups[_config_id(r)].append(r)
    out = []
    for members in groups.values():
        x, _ = _mean_std([as_float((m.get("cost") or {}).get(cost)) for m in members])
        y, _ = _mean_std([chamfer_l2(m) for m in members])
        empty = any(no_result(m) for m in members)
        out.append({"model": str(members[0].get("model")), "shape": shape_name(members[0]), "x": x, "y": y, "empty": empty})
    return out


def plot_pareto(records: list[dict[str, Any]], out_dir: str) -> list[str]:
    """Chamfer L2 against each cost that the records hold (log-log); the non-dominated points joined."""
    axes_with_data = [(c, t) for c, t in COST_AXES
                      if any(p["x"] > 0 and math.isfinite(p["y"]) for p in _config_points(records, c))]
    if not axes_with_data:
        return []
    shapes = sorted({shape_name(r) for r in ok_records(records)})
    colors = _colors(str(r.get("model")) for r in ok_records(records))
    fig, axes = plt.subplots(len(shapes), len(axes_with_data), figsize=(5 * len(axes_with_data), 4 * len(shapes)),
                             squeeze=False)
    for row, shape in zip(axes, shapes):
        for ax, (cost, title) in zip(row, axes_with_data):
            pts = [p for p in _config_points(records, cost) if p["shape"] == shape and p["x"] > 0 and p["y"] > 0]
            labelled = set()
            for p in pts:
                ax.scatter(p["x"], p["y"], color=colors[p["model"]], s=22, zorder=3, marker="x" if p["empty"] else "o",
                           label=p["model"] if p["model"] not in labelled else None)
                labelled.add(p["model"])
            front = pareto_front([p["x"] for p in pts], [math.nan if p["empty"] else p["y"] for p in pts])
            if len(front):
                ax.plot([pts[i]["x"] for i in front], [pts[i]["y"] for i in front], "k-", lw=1, zorder=2,
                        label="Pareto front")
            _floor_line(ax, convergence.floor(records, shape))
            ax.set(xscale="log", yscale="log", xlabel=title, ylabel="chamfer L2 (× = empty mesh, penalty)", title=shape)
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7)
    return _save(fig, out_dir, "pareto")


def sampling_lines(records: list[dict[str, Any]]) -> dict[tuple[str, str], list[tuple[float, float, float]]]:
    """Per (model, strategy) of the ok runs that trained on samples (their record counts them; a family
    that needs none, such as mesh or grid_sdf, records no count): [(n labels, mean chamfer L2, std)] by n."""
    groups: dict[tuple[str, str, float], list[float]] = defaultdict(list)
    for r in ok_records(records):
        s = r.get("sampling") or {}
        n = as_float(s.get("n_samples"))
        if math.isfinite(n) and n > 0:
            groups[(str(r.get("model")), str(s.get("strategy")), n)].append(chamfer_l2(r))
    lines: dict[tuple[str, str], list[tuple[float, float, float]]] = defaultdict(list)
    for (model, strategy, n), vals in groups.items():
        lines[(model, strategy)].append((n, *_mean_std(vals)))
    return {k: sorted(v) for k, v in sorted(lines.items())}


def plot_sampling(records: list[dict[str, Any]], out_dir: str) -> list[str]:
    """Chamfer L2 against the number of training labels, one line per (model, strategy), log-log."""
    lines = sampling_lines(records)
    if not lines:
        return []
    several_models = len({m for m, _ in lines}) > 1
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for (model, strategy), pts in lines.items():
        n, y, e = zip(*pts)
        ax.errorbar(n, y, yerr=e, marker="o", ms=4, capsize=2, label=f"{model} {strategy}" if several_models else strategy)
    _floor_line(ax, convergence.floor(records))
    ax.set(xscale="log", yscale="log", xlabel="training samples (labels)", ylabel="chamfer L2")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, out_dir, "sampling")


def plot_render_time(records: list[dict[str, Any]], out_dir: str) -> list[str]:
    """Cold and warm render time per model (groups) and image size (bars), log axis."""
    groups: dict[tuple[str, str], dict[str, list[float]]] = defaultdict(lambda: {"cold": [], "warm": []})
    for r in ok_records(records):
        c, sc = r.get("cost") or {}, r.get("scene") or {}
        if "render_warm_s" in c:
            size = f"{sc.get('width')}×{sc.get('height')}"
            groups[(str(r.get("model")), size)]["cold"].append(as_float(c.get("render_cold_s")))
            groups[(str(r.get("model")), size)]["warm"].append(as_float(c.get("render_warm_s")))
    if not groups:
        return []
    models = sorted({m for m, _ in groups})
    sizes = sorted({s for _, s in groups}, key=lambda s: int(s.split("×")[0]) if s.split("×")[0].isdigit() else 0)
    bar_w = 0.8 / (2 * len(sizes))
    fig, ax = plt.subplots(figsize=(max(6, 1.4 * len(models) * len(sizes) ** 0.5), 4.5))
    cmap = plt.get_cmap("viridis")
    for j, size in enumerate(sizes):
        color = cmap(j / max(1, len(sizes) - 1) * 0.85)
        for k, kind in enumerate(("cold", "warm")):
            xs = np.arange(len(models)) - 0.4 + bar_w * (2 * j + k + 0.5)
            ys = [_mean_std(groups.get((m, size), {kind: []})[kind])[0] for m in models]
            ax.bar(xs, ys, width=bar_w, color=color, alpha=1.0 if kind == "warm" else 0.45,
                   hatch="" if kind == "warm" else "//", edgecolor="k", lw=0.3, label=f"{size} {kind}")
    ax.set_xticks(np.arange(len(models)), models, rotation=30, ha="right")
    ax.set(yscale="log", ylabel="render time (s)", title="cold (first, setup included) and warm (median) renders")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=len(sizes))
    return _save(fig, out_dir, "render_time")


def plot_frames_by_shape(records: list[dict[str, Any]], out_dir: str) -> list[str]:
    """Warm frame time per shape (groups, sorted by the mesh's face count) and model (bars), log axis; error bars:
    std over seeds."""
    times: dict[tuple[str, str], list[float]] = defaultdict(list)
    faces: dict[str, int] = {}
    for r in ok_records(records):
        warm = as_float((r.get("cost") or {}).get("render_warm_s"))
        if math.isfinite(warm):
            times[(shape_name(r), str(r.get("model")))].append(warm)
        if r.get("model") == "mesh":
            faces[shape_name(r)] = int((r.get("fit") or {}).get("faces") or 0)
    if not times:
        return []
    shapes = sorted({s for s, _ in times}, key=lambda s: (faces.get(s, 0), s))
    models = sorted({m for _, m in times})
    colors, bar_w = _colors(models), 0.8 / len(models)
    fig, ax = plt.subplots(figsize=(max(7, 0.9 * len(shapes) * len(models) ** 0.5), 4.5))
    for k, model in enumerate(models):
        stats = [_mean_std(times.get((s, model), [])) for s in shapes]
        ax.bar(np.arange(len(shapes)) - 0.4 + bar_w * (k + 0.5), [m for m, _ in stats], width=bar_w,
               yerr=[e for _, e in stats], color=colors[model], edgecolor="k", lw=0.3, label=model)
    ax.set_xticks(np.arange(len(shapes)), [f"{s}\n{faces[s]:,} faces" if s in faces else s for s in shapes],
                  rotation=30, ha="right", fontsize=7)
    ax.set(yscale="log", ylabel="warm frame time (s)", title="warm frame (median of repeats) by shape: mean ± std "
           "over seeds")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))  # beside the axes, off the bars
    return _save(fig, out_dir, "frames_by_shape")


def ablation_lines(records: list[dict[str, Any]]) -> dict[str, list[tuple[int, float, float]]]:
    """Per factor of (s_fc, s_dr, s_p): [(level, mean chamfer L2, std)] over the ok surface runs whose
    other two factors sit at their base (lowest) level, by increasing level; {} without surface runs."""
    pts: dict[tuple[int, ...], list[float]] = defaultdict(list)
    for r in ok_records(records):
        s = r.get("sampling") or {}
        if s.get("strategy") == "surface" and all(isinstance(s.get(f), (int, float)) for f in SURFACE_FACTORS):
            pts[tuple(int(s[f]) for f in SURFACE_FACTORS)].append(chamfer_l2(r))
    if not pts:
        return {}
    base = [min(p[i] for p in pts) for i in range(3)]
    return {factor: sorted((p[i], *_mean_std(v)) for p, v in pts.items()
                           if all(p[j] == base[j] for j in range(3) if j != i))
            for i, factor in enumerate(SURFACE_FACTORS)}


def plot_ablation(records: list[dict[str, Any]], out_dir: str) -> list[str]:
    """Chamfer L2 against each of s_fc, s_dr, s_p with the other two at their base level (ablation_lines)."""
    lines = ablation_lines(records)
    if not lines:
        return []
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for factor, line in lines.items():
        lv, y, e = zip(*line)
        ax.errorbar(lv, y, yerr=e, marker="o", capsize=2, label=f"{factor} (the others at their base level)")
    _floor_line(ax, convergence.floor(records))
    ax.set(yscale="log", xlabel="level (samples per point / face / direction)", ylabel="chamfer L2",
           title="surface sampling, one factor at a time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, out_dir, "ablation")


def plot_convergence(records: list[dict[str, Any]], out_dir: str) -> list[str]:
    """Chamfer L2 and F@0.01 probes against fit time per model (rows: shapes): the median over seeds and
    the min–max band, the noise floor dotted (report.convergence)."""
    metrics = (("chamfer_l2", "chamfer L2 (probe)", "log"), ("fscore@0.01", "F@0.01 (probe)", "linear"))
    data = {m: convergence.curves(records, m) for m, _, _ in metrics}
    keys = sorted(set(data["chamfer_l2"]) | set(data["fscore@0.01"]))
    if not keys:
        return []
    shapes = sorted({shape for _, shape in keys})
    colors = _colors(model for model, _ in keys)
    fig, axes = plt.subplots(len(shapes), len(metrics), figsize=(11, 4 * len(shapes)), squeeze=False)
    for row, shape in zip(axes, shapes):
        for ax, (metric, label, yscale) in zip(row, metrics):
            for (model, s), runs in data[metric].items():
                if s != shape:
                    continue
                t, med, lo, hi = convergence.band(runs)
                ax.plot(t, med, "-o", ms=3, color=colors[model], label=f"{model} (n={len(runs)})")
                ax.fill_between(t, lo, hi, color=colors[model], alpha=0.2, step="post")
            _floor_line(ax, convergence.floor(records, shape, metric))
            ax.set(xscale="log", yscale=yscale, xlabel="fit time (s)", ylabel=label,
                   title=f"{shape}: median and min–max over seeds")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7)
    return _save(fig, out_dir, "convergence")


PLOTS: dict[str, Callable[[list[dict[str, Any]], str], list[str]]] = {
    "fit_curves": plot_fit_curves, "pareto": plot_pareto, "sampling": plot_sampling,
    "render_time": plot_render_time, "frames_by_shape": plot_frames_by_shape, "ablation": plot_ablation, "convergence": plot_convergence,
}


def plots_for(experiment: str) -> tuple[str, ...]:
    """The plot kinds an experiment's report gets."""
    return PLOTS_BY_EXPERIMENT.get(experiment, DEFAULT_PLOTS)


def write_plots(records: list[dict[str, Any]], out_dir: str, kinds: Iterable[str]) -> list[str]:
    """Write every plot of `kinds` that has data; return the files written (PNG and PDF)."""
    written: list[str] = []
    for kind in kinds:
        written += PLOTS[kind](records, out_dir)
    return written

"""`python -m ddfbench.report.site [--reports reports] --out site/`: a static results site from the committed reports.

The site opens from the file system with no server (plotly.js is written once beside the pages):

    index.html        what the site holds, links to every page
    pareto.html       accuracy (CD-L2) against warm render time, fit time and bytes, one point per run of every
                      report with compact records (records.jsonl.gz); log axes; per table row (report, model,
                      preset, shape) the geometric mean with its 95 % t interval as error bars; hover names report,
                      family, preset, shape and seed; a legend entry per family toggles its points; a shape selector
    claims.html       reports/claims.md as a table, filterable by verdict
    gallery.html      every committed gallery.png
    <report>.html     one page per report folder with a table.csv: its runs, code commit and whether it regenerates
                      from committed files (ddfbench.report.index), its table and its images

Plots are drawn by plotly (a well-kept library), never by hand.
"""

from __future__ import annotations

import argparse
import html
import json
import math
import os
import re
import shutil
import sys

import numpy as np
import pandas as pd

from ddfbench.core.errors import InputError
from ddfbench.evaluate.metric_registry import by_name
from ddfbench.report import compact, index
from ddfbench.report.stats import summarize_values
from ddfbench.report.tables import label_keys, per_run_of_rows, record_row, varying_keys

PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")
AXES = (("render_warm_s", "warm render s"), ("fit_s", "fit or build s"), ("storage_bytes", "bytes"))
PLOTLY_JS = "plotly.min.js"
STYLE = ("body{font-family:system-ui,sans-serif;margin:1.5em;max-width:1300px}table{border-collapse:collapse;"
         "font-size:13px}td,th{border:1px solid #ccc;padding:3px 6px}nav a{margin-right:1em}img{max-width:100%}")


def page(title: str, body: str, head: str = "") -> str:
    """A complete HTML page with the site's navigation."""
    nav = " ".join(f'<a href="{p}.html">{t}</a>' for p, t in (("index", "home"), ("pareto", "Pareto"),
                                                                ("claims", "claims"), ("gallery", "gallery")))
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{STYLE}</style>{head}</head><body><nav>{nav}</nav><h1>{html.escape(title)}</h1>{body}</body></html>")


def runs(reports: str) -> pd.DataFrame:
    """One row per ok run that gave a result (records.no_result: not an empty mesh, not off the shape) of every report
    below `reports` that holds records.jsonl.gz (column `report`: its folder)."""
    frames = []
    for folder in compact.folders_holding(reports, compact.FILE):
        rows = [record_row(r) for r in compact.records_of(folder)]
        df = per_run_of_rows(rows)
        if df.empty:  # a compact file without a record: no run to plot
            continue
        df.insert(0, "report", os.path.relpath(folder, reports))
        # the table's configuration (tables.summarize: the config keys that vary in the report) and its label (the
        # varying override keys, e.g. capacity=c2): a report's presets of one model are rows of their own
        keys, labels = varying_keys(rows), label_keys(rows)
        df["config"] = ["|".join(json.dumps(r["_config"].get(k), default=str) for k in keys) for r in rows]
        df["preset"] = [", ".join(f"{k}={r['_labels'].get(k)}" for k in labels) for r in rows]
        # a run that gave no mesh, or one off the shape, is not a method result: its penalty is not plotted; the
        # mean of its configuration says how many of its ok runs (the table's n) it leaves out
        ok = df[df["status"] == "ok"].copy()
        ok["lost"] = ok["empty"].astype(bool) | ok["off"].astype(bool)
        cell = ok.groupby(["model", "shape", "config"], dropna=False)["lost"]
        ok["n_ok"], ok["n_left_out"] = cell.transform("size"), cell.transform("sum")
        frames.append(ok[~ok["lost"]].drop(columns="lost"))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _named(model: str, preset: str) -> str:
    """A model with its preset label where the report varies one (`ddf_tuned (capacity=c2)`)."""
    return f"{model} ({preset})" if preset else model


def _left_out(cell: pd.DataFrame) -> str:
    """The runs of a configuration its mean leaves out, in words ('' for none): the table's mean counts them."""
    lost, n = int(cell["n_left_out"].iloc[0]), int(cell["n_ok"].iloc[0])
    return f"<br>{lost} of its {n} runs left out (no mesh or off the shape): the table's mean counts them" * bool(lost)


def pareto_figure(df: pd.DataFrame, x: str, x_label: str):
    """The figure of CD-L2 x10^3 against column x: per family and shape one trace of runs (legend group = family)
    and one of (report, model, configuration) geometric means with interval bars, as the table's rows; a dropdown
    shows one shape or all."""
    import plotly.graph_objects as go

    data = df[np.isfinite(df[x].astype(float)) & np.isfinite(df["chamfer_l2"].astype(float))
              & (df[x].astype(float) > 0) & (df["chamfer_l2"].astype(float) > 0)]
    fig = go.Figure()
    shapes = sorted(data["shape"].unique())
    colors = {f: PALETTE[i % len(PALETTE)] for i, f in enumerate(sorted(df["family"].unique()))}  # one per family
    trace_shapes: list[str] = []
    for family, fam in data.groupby("family", sort=True):
        for shape, part in fam.groupby("shape", sort=True):
            hover = [f"{r.report}: {r.family} / {_named(r.model, r.preset)}<br>shape {r.shape}, seed {r.seed}"
                     for r in part.itertuples()]
            fig.add_trace(go.Scatter(x=part[x], y=1e3 * part["chamfer_l2"], mode="markers", name=family,
                                     legendgroup=family, showlegend=shape == fam["shape"].min(), text=hover,
                                     hoverinfo="text+x+y", marker={"size": 7, "opacity": 0.55, "color": colors[family]},
                                     meta={"kind": "runs", "family": family, "shape": shape}))
            trace_shapes.append(shape)
            means = []
            for (model, report, _), cell in part.groupby(["model", "report", "config"], sort=True):
                # geometric mean over seeds and the exponentiated t interval of the mean log: bars stay above 0 on
                # the log axis; one seed: no bar
                s = summarize_values(np.log(1e3 * cell["chamfer_l2"].astype(float)))
                center = math.exp(s.mean)
                up, down = ((math.exp(s.hi) - center, center - math.exp(s.lo)) if s.n > 1 else (math.nan, math.nan))
                means.append((cell[x].astype(float).mean(), center, up, down,
                              f"{report}: {family} / {_named(model, cell['preset'].iloc[0])}, {shape}: "
                              f"geometric mean of {s.n} seed(s)"
                              + (", 95 % t interval of the mean log" if s.n > 1 else ", no interval")
                              + _left_out(cell)))
            mx, my, up, down, mt = zip(*means)
            fig.add_trace(go.Scatter(x=mx, y=my, mode="markers", name=family, legendgroup=family, showlegend=False,
                                     error_y={"type": "data", "array": list(up), "arrayminus": list(down),
                                              "visible": True}, text=list(mt),
                                     hoverinfo="text+x+y", marker={"size": 11, "symbol": "diamond-open",
                                                                   "color": colors[family]},
                                     meta={"kind": "means", "family": family, "shape": shape}))
            trace_shapes.append(shape)
    buttons = [{"label": "all shapes", "method": "restyle", "args": [{"visible": [True] * len(trace_shapes)}]}]
    buttons += [{"label": s, "method": "restyle", "args": [{"visible": [t == s for t in trace_shapes]}]} for s in shapes]
    fig.update_layout(xaxis={"type": "log", "title": x_label}, yaxis={"type": "log", "title": "CD-L2 ×10³"},
                      legend={"groupclick": "togglegroup", "title": "family (click to hide)"}, height=480,
                      updatemenus=[{"buttons": buttons, "x": 1.0, "y": 1.15, "xanchor": "right"}],
                      margin={"t": 60}, title=f"accuracy against {x_label}")
    return fig


def write_pareto(df: pd.DataFrame, out: str) -> int:
    """pareto.html with one figure per axis that any run has; returns the number of run points plotted."""
    parts, points = [], 0
    for x, label in AXES:
        if x not in df or not np.isfinite(df[x].astype(float)).any():
            continue
        fig = pareto_figure(df, x, label)
        points += sum(len(t.x) for t in fig.data if t.meta["kind"] == "runs")
        parts.append(fig.to_html(full_html=False, include_plotlyjs=False, div_id=f"pareto-{x}"))
    body = (f"<p>One small point per run that gave a mesh on the shape ({len(df)} runs of the reports with records: "
            f"{html.escape(', '.join(sorted(df['report'].unique())) if len(df) else 'none')}); diamonds: the geometric "
            "mean per report, preset and shape with the 95 % t interval of its mean log (no bar: one seed). Lower left "
            "is better.</p>" + "".join(parts))
    with open(os.path.join(out, "pareto.html"), "w") as fh:
        fh.write(page("Accuracy against cost", body, head=f"<script src='{PLOTLY_JS}'></script>"))
    return points


def markdown_table(md: str) -> pd.DataFrame:
    """The first pipe table of a markdown text as a DataFrame of strings (bold marks and backticks dropped)."""
    lines = [ln for ln in md.splitlines() if ln.startswith("|")]
    if len(lines) < 2:
        return pd.DataFrame()

    def cells(line: str) -> list[str]:
        return [re.sub(r"\*\*|`", "", c).strip() for c in line.strip().strip("|").split(" | ")]

    header = cells(lines[0])
    return pd.DataFrame([c for c in map(cells, lines[2:]) if len(c) == len(header)], columns=header)


def write_claims(reports: str, out: str) -> None:
    """claims.html: the claims table with a verdict filter."""
    path = os.path.join(reports, "claims.md")
    table = markdown_table(open(path).read()) if os.path.isfile(path) else pd.DataFrame()
    verdicts = sorted(table["verdict"].unique()) if "verdict" in table else []
    options = "".join(f"<option>{html.escape(v)}</option>" for v in verdicts)
    rows = table.to_html(index=False, escape=True, table_id="claims") if len(table) else "<p>no claims table</p>"
    script = ("<script>function filt(v){document.querySelectorAll('#claims tbody tr').forEach(function(r){"
              "var c=r.cells[" + str(list(table.columns).index("verdict") if "verdict" in table else 0) + "];"
              "r.style.display=(!v||c.textContent.trim()===v)?'':'none';});}</script>")
    body = (f"<p>The source papers' claims tested against ddfbench's records (reports/claims.md).</p>"
            f"<label>verdict <select id='verdict' onchange='filt(this.value)'><option value=''>all</option>{options}"
            f"</select></label>{rows}{script}")
    with open(os.path.join(out, "claims.html"), "w") as fh:
        fh.write(page("Claims", body))


def table_folders(reports: str) -> list[str]:
    """Every folder below reports with a table.csv (a page each), relative to reports, sorted."""
    return sorted(os.path.relpath(f, reports) for f, _, files in compact.walk_visible(reports) if "table.csv" in files)


def _slug(rel: str) -> str:
    return "report-" + rel.replace(os.sep, "-")


def provenance_line(found: index.Provenance) -> str:
    """A report folder's runs, code commit(s) and whether it regenerates from committed files, in words."""
    where = {index.REGENERATES: "it regenerates from its committed records",
             index.FROM_ROWS: "a re-measurement of the runs' artifacts; it regenerates from the rows it measured",
             index.FROM_TRIALS: "a tuning study; it regenerates from its committed trial table",
             index.ARTIFACTS: "a re-measurement of the runs' artifacts, which stay with the runs"}.get(
        found.regenerates, "its records are not committed, so its table cannot be recomputed from the repository")
    return (f"{found.runs if found.runs is not None else 'an unknown number of'} runs of code "
            f"{', '.join(found.commits) or 'unknown'}; {where}")


def blank_not_converged(table: pd.DataFrame) -> pd.DataFrame:
    """table.csv with the penalised metrics of its not_converged rows blank (NaN), as tables.to_markdown shows them:
    a penalty is not a method result."""
    if "not_converged" not in table:
        return table
    dead, table = table["not_converged"].astype(bool), table.copy()
    for name, metric in by_name().items():
        if metric.penalty is not None:
            table.loc[dead, [c for c in table.columns if c.startswith(f"{name}_")]] = math.nan
    return table


def write_reports(reports: str, out: str) -> list[tuple[str, str, index.Provenance]]:
    """One page per report folder: its provenance, its table.csv and its images (copied under img/). Returns
    (page name, folder relative to reports, provenance) per page."""
    pages = []
    for rel in table_folders(reports):
        folder, slug = os.path.join(reports, rel), _slug(rel)
        found = index.provenance(folder)
        images = []
        for name in sorted(f for f in os.listdir(folder) if f.endswith(".png")):
            target = os.path.join("img", f"{slug}-{name}")
            shutil.copy2(os.path.join(folder, name), os.path.join(out, target))
            images.append(f"<p><img src='{target}' alt='{html.escape(rel)} {name}'></p>")
        table = blank_not_converged(pd.read_csv(os.path.join(folder, "table.csv")))
        shown = [c for c in table.columns if not c.endswith(("_ci_lo", "_ci_hi", "_std")) and c != "keys"]
        note = (" A row not_converged (every run empty or off the shape) is no method result and is not ranked: its "
                "geometry cells are blank, as in the report's table.md (table.csv keeps the penalty)."
                if "not_converged" in table and table["not_converged"].astype(bool).any() else "")
        body = (f"<p>From <code>reports/{html.escape(rel)}</code>: {provenance_line(found)}.{note}</p>"
                + table[shown].to_html(index=False, float_format=lambda v: f"{v:.4g}", na_rep="–") + "".join(images))
        with open(os.path.join(out, f"{slug}.html"), "w") as fh:
            fh.write(page(rel, body))
        pages.append((slug, rel, found))
    return pages


def write_gallery(reports: str, out: str) -> int:
    """gallery.html: every report's gallery.png (copied under img/); returns how many."""
    found = sorted(os.path.relpath(f, reports) for f, _, files in compact.walk_visible(reports)
                   if "gallery.png" in files)
    parts = []
    for rel in found:
        target = os.path.join("img", f"{_slug(rel)}-gallery.png")
        shutil.copy2(os.path.join(reports, rel, "gallery.png"), os.path.join(out, target))
        parts.append(f"<h2>{html.escape(rel)}</h2><img class='gallery' src='{target}' alt='gallery of {html.escape(rel)}'>")
    with open(os.path.join(out, "gallery.html"), "w") as fh:
        fh.write(page("Gallery", "".join(parts) or "<p>no gallery</p>"))
    return len(found)


def write_site(reports: str, out: str) -> dict[str, int]:
    """Write the whole site into out; returns {"runs": plotted run points, "pages": report pages, "galleries": n}."""
    import plotly

    os.makedirs(os.path.join(out, "img"), exist_ok=True)
    shutil.copy2(os.path.join(os.path.dirname(plotly.__file__), "package_data", PLOTLY_JS), os.path.join(out, PLOTLY_JS))
    df = runs(reports)
    points = write_pareto(df, out)
    write_claims(reports, out)
    galleries = write_gallery(reports, out)
    pages = write_reports(reports, out)
    links = "".join(f"<li><a href='{slug}.html'>{html.escape(rel)}</a>"
                    f"{'' if found.regenerates in index.REGENERABLE else ' (not regenerable from records)'}</li>"
                    for slug, rel, found in pages)
    body = ("<p>ddfbench: which shape representation, at what cost. <a href='pareto.html'>Accuracy against cost</a>, "
            "<a href='claims.html'>the papers' claims</a>, <a href='gallery.html'>galleries</a>, and every report:</p>"
            f"<ul>{links}</ul>")
    with open(os.path.join(out, "index.html"), "w") as fh:
        fh.write(page("ddfbench results", body))
    return {"runs": points, "pages": len(pages), "galleries": galleries}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.site", description=__doc__.split("\n")[0])
    parser.add_argument("--reports", default="reports", help="the committed reports (default: reports)")
    parser.add_argument("--out", required=True, help="folder to write the site into (open its index.html)")
    parser.add_argument("--screenshot", help="also save a PNG of the Pareto page there (headless Chromium, Selenium)")
    args = parser.parse_args(argv)
    from ddfbench.run.checks import writable_folder  # (it imports the families: torch)

    if not os.path.isdir(args.reports):
        what = "is a file, not a folder" if os.path.exists(args.reports) else "no such folder"
        print(f"ddfbench.report.site: --reports {args.reports}: {what}", file=sys.stderr)
        return 2
    try:
        writable_folder(args.out, "--out ")
        got = write_site(args.reports, args.out)
    except InputError as exc:
        print(f"ddfbench.report.site: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}/index.html: {got['runs']} run points, {got['pages']} report pages, "
          f"{got['galleries']} galleries", flush=True)
    if args.screenshot:
        screenshot(os.path.join(os.path.abspath(args.out), "pareto.html"), args.screenshot)
    return 0


def screenshot(page_path: str, png: str, width: int = 1300, height: int = 1100) -> None:
    """Save a PNG of a page as headless Chromium draws it (Debian's chromium and chromium-driver)."""
    import time

    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium") or "chromium"
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", f"--window-size={width},{height}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(shutil.which("chromedriver") or "chromedriver"), options=options)
    try:
        driver.get(f"file://{page_path}")
        time.sleep(1.0)  # plotly draws after load
        driver.save_screenshot(png)
    finally:
        driver.quit()


if __name__ == "__main__":
    sys.exit(main())

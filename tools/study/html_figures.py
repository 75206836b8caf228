"""report.html's interactive figures (plotly): the same data and colours as the PNG figures
(tools/study/figure_data.py), made to zoom into a run and hover a value. Each returns the figure as
plotly's JSON, which report.html hands to the inlined plotly.js. SVG traces only: WebGL may be
missing where the report is read (a headless browser, a remote desktop)."""

from __future__ import annotations

from typing import Any

import numpy as np

from tools.study.figure_data import (BAR_METRICS, ENVELOPE_S, METRIC_TEXT, METRIC_UNITS, answer_bars, colour_of,
                                     decimate, metric_bars, stopped_early)
from tools.study.config import ESTIMATING
from gen.lib.escape import plotly_text as pt

POINTS = 600  # samples per envelope trace: each the max over its block, so no peak is lost
FONT = {"size": 11}


def _figure(rows: int, cols: int = 1, **kw: Any) -> Any:
    from plotly.subplots import make_subplots

    return make_subplots(rows=rows, cols=cols, **kw)


def _layout(fig: Any, title: str, height: int) -> str:
    """The title at the top, the legend (toggles a method) under it, above every panel."""
    total = height + 110
    fig.update_layout(title={"text": title, "font": {"size": 13}, "y": 1 - 8 / total, "yanchor": "top",
                             "yref": "container"},
                      height=total, font=FONT, template="plotly_white", hovermode="closest",
                      margin={"l": 70, "r": 20, "t": 110, "b": 40},
                      legend={"orientation": "h", "y": 1 - 36 / total, "yanchor": "top", "yref": "container", "x": 0,
                              "font": {"size": 10}})
    return fig.to_json()


def envelope_figure(study: dict[str, Any], scenario: str, kind: str, series: dict[str, dict[str, np.ndarray]],
                    env: dict[str, np.ndarray]) -> str:
    """Tracking ("tracking", deg) or estimation ("estimation", rad/s^2) envelopes per joint, every
    method a line in its colour (the legend toggles it on every joint), a run the safety layer
    stopped crossed where it stopped, the tracking bound dashed."""
    import plotly.graph_objects as go

    n = study["arm"]["n_joints"]
    names = [pt(x) for x in study["arm"]["joint_names"]]
    colour = colour_of(study)
    runs = study["scenarios"][scenario]["runs"]
    methods = [m for m in (ESTIMATING if kind == "estimation" else study["methods"]) if m in env]
    unit = "deg" if kind == "tracking" else "rad/s^2"
    fig = _figure(n, shared_xaxes=True, vertical_spacing=0.015)
    for m in methods:
        t, y = decimate(series[m]["t"], env[m], POINTS)
        r = runs[m][0].get("result") if runs.get(m) else None
        stopped = stopped_early(series[m]["t"], study)
        label = pt(m if r == "ok" else f"{m} ({r}{', stopped' if stopped else ''})")
        for j in range(n):
            fig.add_trace(go.Scatter(x=t.astype(np.float32), y=y[:, j].astype(np.float32), mode="lines", name=label,
                                     legendgroup=m, showlegend=j == 0, line={"color": colour[m], "width": 1.3},
                                     hovertemplate=f"{pt(m)}, {names[j]}: %{{y:.3g}} {unit} at %{{x:.3f}} s<extra></extra>"),
                          row=j + 1, col=1)
            if stopped:
                fig.add_trace(go.Scatter(x=[float(t[-1])], y=[float(y[-1, j])], mode="markers", legendgroup=m,
                                         showlegend=False, marker={"symbol": "x", "size": 11, "color": colour[m],
                                                                   "line": {"width": 1, "color": "black"}},
                                         hovertemplate=f"{pt(m)} stopped here: %{{x:.3f}} s<extra></extra>"),
                              row=j + 1, col=1)
    bound = next((r[0]["bounds"]["max_error_deg"] for r in runs.values() if r and r[0].get("bounds")), None)
    for j in range(n):
        fig.update_yaxes(type="log", dtick=1, exponentformat="power", title_text=f"{j + 1} {names[j]}",
                         title_font={"size": 10}, row=j + 1,
                         col=1)
        if kind == "tracking" and bound:
            fig.add_hline(y=bound, line={"dash": "dash", "width": 1, "color": "black"}, row=j + 1, col=1)
    fig.update_xaxes(title_text="t (s), after the hold", row=n, col=1)
    what = "max |e|" if kind == "tracking" else "max |w - w_hat|"
    return _layout(fig, f"{pt(scenario)}: {what} over {ENVELOPE_S * 1e3:g} ms ({unit}), seed {study['seeds'][0]}"
                        + (f"; dashed: the tracking bound {bound:g} deg" if kind == "tracking" and bound else "")
                        + "; x: where the safety layer stopped a run", 130 * n + 120)


def answer_figure(study: dict[str, Any]) -> str:
    """The answer drawn: per scenario, each method's L-infinity tracking error summed over the
    joints, the mean over the seeds with its 95 % interval; a method some of whose runs did not end
    ok hatched; a log scale where the means span more than 30x."""
    import plotly.graph_objects as go

    colour = colour_of(study)
    groups, bars = answer_bars(study)
    fig = _figure(1)
    for m, b in bars.items():
        bad = any(b["not_ok"])
        fig.add_trace(go.Bar(x=[pt(g) for g in groups], y=b["mean"], name=pt(m + (" (some runs not ok)" if bad else "")),
                             marker_color=colour[m], marker_pattern_shape=["/" if k else "" for k in b["not_ok"]],
                             error_y={"type": "data", "array": np.nan_to_num(b["above"]),
                                      "arrayminus": np.nan_to_num(b["below"]), "thickness": 1, "width": 3},
                             hovertemplate=f"{pt(m)}, %{{x}}: %{{y:.4g}} deg<extra></extra>"))
    vals = np.concatenate([b["mean"] for b in bars.values()]) if bars else np.array([])
    vals = vals[np.isfinite(vals) & (vals > 0)]
    log = bool(len(vals)) and vals.max() / vals.min() > 30
    fig.update_yaxes(title_text="deg", type="log" if log else "linear", dtick=1 if log else None)
    fig.update_layout(barmode="group")
    return _layout(fig, f"Tracking error per scenario (L-inf, summed over joints): mean of {len(study['seeds'])}, "
                        "95 % interval", 330)


def metrics_figure(study: dict[str, Any], scenario: str) -> str:
    """Every metric per joint as grouped bars, the mean over the seeds with its 95 % interval; a
    method some of whose runs did not end ok hatched."""
    import plotly.graph_objects as go

    colour = colour_of(study)
    fig = _figure(len(BAR_METRICS), subplot_titles=[f"{METRIC_TEXT[m]}: mean, 95 % interval" for m in BAR_METRICS],
                  vertical_spacing=0.07)
    shown: set[str] = set()
    for row, metric in enumerate(BAR_METRICS, start=1):
        groups, bars = metric_bars(study, scenario, metric)
        groups = [pt(g) for g in groups]
        for m, b in bars.items():
            bad = b["not_ok"] > 0
            fig.add_trace(go.Bar(x=groups, y=b["mean"], name=pt(m + (f" ({b['not_ok']} of {b['runs']} runs not ok)"
                                                                     if bad else "")),
                                 legendgroup=m, showlegend=m not in shown, marker_color=colour[m],
                                 marker_pattern_shape="/" if bad else "",
                                 error_y={"type": "data", "array": np.nan_to_num(b["above"]),
                                          "arrayminus": np.nan_to_num(b["below"]), "thickness": 1, "width": 3},
                                 hovertemplate=f"{pt(m)}, %{{x}}: %{{y:.4g}} {METRIC_UNITS[metric]}<extra></extra>"),
                          row=row, col=1)
            shown.add(m)
        vals = np.concatenate([b["mean"] for b in bars.values()]) if bars else np.array([])
        vals = vals[np.isfinite(vals) & (vals > 0)]
        log = bool(len(vals)) and vals.max() / vals.min() > 30
        fig.update_yaxes(title_text=METRIC_UNITS[metric], type="log" if log else "linear", dtick=1 if log else None,
                         row=row, col=1)
    fig.update_layout(barmode="group")
    return _layout(fig, f"{pt(scenario)}: every metric per joint over {len(study['seeds'])} seed(s) (hatched: a method "
                        "some of whose runs did not end ok)", 1100)


def distribution_figure(study: dict[str, Any], scenario: str) -> str:
    """Per joint, each method's L-infinity error over the seeds: a box and every seed's point
    (hover: its seed), a run that did not end ok an x."""
    import plotly.graph_objects as go

    sc = study["scenarios"][scenario]
    names = [pt(x) for x in study["arm"]["joint_names"]]
    colour = colour_of(study)
    fig = _figure(1, len(names), subplot_titles=names, horizontal_spacing=0.03)
    for j in range(len(names)):
        for m in study["methods"]:
            vals = sc["stats"][m]["linf"]["per_joint"][j]["values"]
            res = sc["stats"][m]["results"]
            pts = [(s, float(np.degrees(v)), r) for s, v, r in zip(study["seeds"], vals, res)
                   if v is not None and np.isfinite(v)]
            if not pts:
                continue
            fig.add_trace(go.Box(y=[p[1] for p in pts], name=pt(m), legendgroup=m, showlegend=j == 0,
                                 boxpoints="all", jitter=0.3, pointpos=0, marker={"color": colour[m], "size": 4},
                                 line={"color": colour[m]}, text=[pt(f"seed {p[0]}: {p[2]}") for p in pts],
                                 hovertemplate=f"{pt(m)}, {names[j]}: %{{y:.4g}} deg, %{{text}}<extra></extra>"),
                          row=1, col=j + 1)
            bad = [p for p in pts if p[2] != "ok"]
            if bad:
                fig.add_trace(go.Scatter(x=[pt(m)] * len(bad), y=[p[1] for p in bad], mode="markers", showlegend=False,
                                         legendgroup=m, marker={"symbol": "x", "size": 10, "color": "black"},
                                         text=[pt(f"seed {p[0]}: {p[2]}") for p in bad],
                                         hovertemplate="%{text}<extra></extra>"), row=1, col=j + 1)
        fig.update_yaxes(type="log", dtick=1, row=1, col=j + 1)
        fig.update_xaxes(showticklabels=False, row=1, col=j + 1)
    fig.update_yaxes(title_text="L-inf tracking error (deg)", row=1, col=1)
    return _layout(fig, f"{pt(scenario)}: L-infinity tracking error per joint, one point per seed (x: a run that did "
                        "not end ok)", 460)


def tuning_figure(scenario: str, recs: dict[str, dict[str, Any]], colour: dict[str, str]) -> str:
    """Each tuned method's best objective so far over its trials (log scale)."""
    import plotly.graph_objects as go

    fig = _figure(1)
    for m, r in recs.items():
        curve = np.asarray(r.get("best_so_far") or [], dtype=float)
        if not curve.size:
            continue
        fig.add_trace(go.Scatter(x=np.arange(1, curve.size + 1), y=curve, mode="lines", line_shape="hv",
                                 name=pt(f"{m}: {r.get('status', '?')}, best {curve[-1]:.4g}"),
                                 line={"color": colour.get(m, "#333")},
                                 hovertemplate=f"{pt(m)}: trial %{{x}}, best so far %{{y:.4g}}<extra></extra>"))
    fig.update_yaxes(type="log", dtick=1, title_text="best objective so far (sum L-inf, rad; >= 1000: failed)")
    fig.update_xaxes(title_text="trial (every round, in order)")
    return _layout(fig, f"{pt(scenario)}: tuning, the best objective so far", 420)

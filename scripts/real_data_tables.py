#!/usr/bin/env python3
"""The real-data study's tables (scripts/real_data_study.sh): markdown from the
JSON reports `arena evaluate` and `arena calibrate` wrote, and --check: the
same tables in a document, every figure compared but wall times."""
import argparse
import json
import math
import re
import sys

DEG = 180 / math.pi
BEGIN, END = "<!-- real-data-study:begin -->", "<!-- real-data-study:end -->"
# The reference: an exact quasi-static limit-surface model on these 50 trials
# (issue 30's target), fed the same starts and pusher paths.
REFERENCE = {"nmse": 0.056, "pos": (2.5, 8.0), "ang": (2.3, 14.8), "mu_pusher": 0.286}


def load(path):
    with open(path) as f:
        return json.load(f)


def f3(v):
    return "-" if v is None else f"{v:.3f}"


def pair(d, scale, fmt="{:.2f}/{:.2f}"):
    if not d:
        return "-"
    return fmt.format(d["median"] * scale, d["p95"] * scale)


def nmse_cells(n):
    if not n or n.get("value") is None:
        return ["-", "-"]
    return [f3(n["value"]), f"{n['dx']:.3f}/{n['dy']:.3f}/{n['dtheta']:.3f}"]


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


EVAL_HEADER = ["predictor", "setting", "scored", "NMSE", "NMSE dx/dy/dθ", "position mm med/p95",
               "angle ° med/p95", "force N med/p95 (trials)", "ms/trial med"]


def eval_rows(settings):
    rows = []
    for s in settings:
        force = "-"
        if s.get("force_error_n"):
            force = pair(s["force_error_n"], 1) + f" ({s['force_trials']})"
        rows.append([s["predictor"], s["model_key"], f"{s['ok']}/{s['trials']}",
                     *nmse_cells(s.get("outcome_nmse")), pair(s["position_error_m"], 1e3),
                     pair(s["angle_error_rad"], DEG), force,
                     f"{s['time_s']['median'] * 1e3:.0f}"])
    return rows


def by_shape(report):
    rows = []
    for g in report["groups"]:
        for r in eval_rows(g["settings"]):
            rows.append([g["value"]] + r)
    return table(["shape"] + EVAL_HEADER, rows)


def figures_cells(f):
    n = f.get("outcome_nmse")
    return [f3(n["value"]) if n else "-",
            f"{f['position_error_m']['median'] * 1e3:.2f}/{f['position_error_m']['p95'] * 1e3:.2f}",
            f"{f['angle_error_rad']['median'] * DEG:.2f}/{f['angle_error_rad']['p95'] * DEG:.2f}"]


def fitted_text(params):
    parts = []
    for name, p in sorted(params.items()):
        if "value" in p:
            parts.append(f"{name} {p['value']:.3f}")
        else:
            parts.append(f"{name} x{p['scale']:.3f}")
    return ", ".join(parts)


def build(work, settings_text):
    before = load(f"{work}/evaluate_before.json")
    after = load(f"{work}/evaluate_after.json")
    after_mujoco = load(f"{work}/evaluate_after_mujoco.json")
    after["settings"] += after_mujoco["settings"]
    for g, gm in zip(after["groups"], after_mujoco["groups"]):
        assert g["value"] == gm["value"]
        g["settings"] += gm["settings"]
    cal_all = load(f"{work}/calibrate_all.json")
    cal_shape = load(f"{work}/calibrate_by_shape.json")
    import sqlite3
    con = sqlite3.connect(f"file:{work}/real.db?mode=ro", uri=True)
    done, planned = con.execute(
        "SELECT sum(state = 'done'), count(*) FROM trials WHERE campaign_id = 1").fetchone()
    md = []
    md.append(f"Settings: {settings_text}. Trials done on the replay cells: {done} of {planned}.\n")
    md.append("**Before calibration** (the import's starting values, `mu_pusher` = "
              "`mu_support` = 0.25), all trials:\n")
    md.append("`arena evaluate --db real.db --campaign 1 --predictors arena,mujoco --facets 8 --dt 0.016,0.008 "
              "--mujoco-timestep 0.002 --group-by shape --trial-parameters "
              "DATASET/trials.csv`\n")
    md.append(table(EVAL_HEADER, eval_rows(before["settings"])) + "\n")
    md.append("Per shape (the same command; each shape's NMSE over its own trials' variance):\n")
    md.append(by_shape(before) + "\n")
    rep = cal_all["report"]
    md.append("**Calibrated on every trial, scored on the same trials** (the reference's "
              "protocol):\n")
    md.append("`arena calibrate --db real.db --campaign 1 --params mu_pusher,pressure_rim --loss nmse --max-evaluations 20 --lower 0.05 "
              "--holdout 0 --predictor-settings '{\"dt\": 0.016}'`\n")
    nominal = ", ".join(f"{n} {p['nominal']:.3f}" for n, p in sorted(cal_all["params"].items())
                        if "nominal" in p)
    rows = [["arena g8_k3_dt0.016, before", nominal] + figures_cells(rep["train_figures"]["before"]),
            ["arena g8_k3_dt0.016, after", fitted_text(cal_all["params"])] +
            figures_cells(rep["train_figures"]["after"]),
            ["reference (quasi-static limit surface)", f"mu_pusher {REFERENCE['mu_pusher']}",
             f"{REFERENCE['nmse']:.3f}", "%.2f/%.2f" % REFERENCE["pos"], "%.2f/%.2f" % REFERENCE["ang"]]]
    md.append(table(["model", "friction", "NMSE", "position mm med/p95", "angle ° med/p95"], rows) + "\n")
    mu = cal_all["params"]["mu_pusher"]["scale"]
    md.append(f"**After calibration**: arena with calibration {cal_all['id']}'s scales on every "
              "scene; MuJoCo with its pusher friction alone (MuJoCo spreads the support's load by "
              "its own contacts and refuses a weighted pressure):\n")
    md.append(f"`arena evaluate ... --predictors arena --calibration {cal_all['id']}` and "
              f"`arena evaluate ... --predictors mujoco --scale mu_pusher={mu:.6g}` (otherwise as "
              "before)\n")
    md.append(table(EVAL_HEADER, eval_rows(after["settings"])) + "\n")
    md.append(by_shape(after) + "\n")
    md.append("**Held out by shape** (fit on three shapes, score on the fourth, all four ways; each "
              "held-out NMSE over that shape's own trials; pooled: every trial predicted by the fit "
              "that did not see its shape, NMSE over all 50):\n")
    md.append("`arena calibrate --db real.db --campaign 1 --params mu_pusher,pressure_rim --loss nmse --max-evaluations 20 --lower 0.05 "
              "--holdout-by shape --trial-parameters DATASET/trials.csv --predictor-settings "
              "'{\"dt\": 0.016}'`\n")
    rows = []
    for sp in cal_shape["splits"]:
        r = sp["report"]
        rows.append([sp["split"]["heldout_value"], len(r["heldout_ids"]), fitted_text(sp["params"]),
                     figures_cells(r["heldout_figures"]["before"])[0]] +
                    figures_cells(r["heldout_figures"]["after"]))
    pb, pa = cal_shape["pooled_heldout"]["before"], cal_shape["pooled_heldout"]["after"]
    rows.append(["pooled", pa["trials"], "-", figures_cells(pb)[0]] + figures_cells(pa))
    md.append(table(["held out", "trials", "fitted on the other three", "NMSE before", "NMSE after",
                     "position mm med/p95", "angle ° med/p95"], rows) + "\n")
    key, far = where_far(work)
    md.append(f"**Where the calibrated model is far from the data** (arena {key} after "
              "calibration, per shape and push angle, from the evaluation's per-trial results):\n")
    md.append(far + "\n")
    return "\n".join(md)


COLOURS = {"rect1": "#1f77b4", "hex": "#2ca02c", "ellip1": "#ff7f0e", "ellip3": "#d62728"}


def plot(work, out_svg):
    """Where the calibrated model is far from the data: per trial, the
    predicted against the measured turn, and the final errors against the
    push angle, by shape (arena at the first setting, after calibration)."""
    import csv
    import sqlite3
    csv.field_size_limit(1 << 30)
    after = load(f"{work}/evaluate_after.json")
    key = after["settings"][0]["model_key"]
    params = {}
    with open(f"{work}/dataset/trials.csv", newline="") as f:
        for row in csv.DictReader(f):
            params[row["seed"]] = (row["shape"], float(row["push_angle_rad"]))
    con = sqlite3.connect(f"file:{work}/real.db?mode=ro", uri=True)
    points = []
    for seed, detail, pos, ang in con.execute(
            "SELECT t.seed, r.detail_json, r.final_position_error, r.final_angle_error "
            "FROM evaluation_results r JOIN trials t ON t.id = r.trial_id "
            "WHERE r.evaluation_id = ? AND r.model_key = ? AND r.status = 'ok'",
            (after["evaluation_id"], key)):
        o = json.loads(detail).get("outcome")
        if not o:
            continue
        shape, angle = params[str(seed)]
        points.append((shape, angle * DEG, o["true"][2] * DEG, o["predicted"][2] * DEG, pos * 1e3,
                       ang * DEG))
    w, h, m = 330, 300, 48
    panels = [
        ("turn: predicted against measured (°)", lambda p: p[2], lambda p: p[3], (-45, 45),
         (-45, 45), True),
        ("final position error (mm) by push angle (°)", lambda p: p[1], lambda p: p[4], (-90, 90),
         (0, 12), False),
        ("final angle error (°) by push angle (°)", lambda p: p[1], lambda p: p[5], (-90, 90),
         (0, 30), False)]
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{3 * w}" height="{h + 40}" '
           'font-family="sans-serif" font-size="11">',
           f'<rect width="{3 * w}" height="{h + 40}" fill="white"/>']
    for k, (title, fx, fy, (x0, x1), (y0, y1), diagonal) in enumerate(panels):
        ox = k * w

        def sx(v):
            return ox + m + (v - x0) / (x1 - x0) * (w - m - 12)

        def sy(v):
            return h - m + 10 - (min(max(v, y0), y1) - y0) / (y1 - y0) * (h - m - 20)
        svg.append(f'<text x="{ox + w / 2}" y="16" text-anchor="middle" font-weight="bold">'
                   f'{title}</text>')
        svg.append(f'<rect x="{sx(x0)}" y="{sy(y1)}" width="{sx(x1) - sx(x0)}" '
                   f'height="{sy(y0) - sy(y1)}" fill="none" stroke="#888"/>')
        for i in range(5):
            xv = x0 + (x1 - x0) * i / 4
            yv = y0 + (y1 - y0) * i / 4
            svg.append(f'<text x="{sx(xv)}" y="{sy(y0) + 14}" text-anchor="middle">{xv:g}</text>')
            svg.append(f'<text x="{sx(x0) - 4}" y="{sy(yv) + 4}" text-anchor="end">{yv:g}</text>')
        if diagonal:
            svg.append(f'<line x1="{sx(x0)}" y1="{sy(y0)}" x2="{sx(x1)}" y2="{sy(y1)}" '
                       'stroke="#bbb" stroke-dasharray="4 3"/>')
        for p in points:
            svg.append(f'<circle cx="{sx(fx(p)):.1f}" cy="{sy(fy(p)):.1f}" r="3.5" '
                       f'fill="{COLOURS.get(p[0], "#555")}" fill-opacity="0.8"/>')
    for i, (shape, colour) in enumerate(COLOURS.items()):
        svg.append(f'<circle cx="{60 + 90 * i}" cy="{h + 22}" r="4" fill="{colour}"/>'
                   f'<text x="{68 + 90 * i}" y="{h + 26}">{shape}</text>')
    svg.append(f'<text x="{3 * w - 10}" y="{h + 26}" text-anchor="end">arena {key}, calibrated; '
               f'{len(points)} trials</text>')
    svg.append("</svg>")
    with open(out_svg, "w") as f:
        f.write("\n".join(svg) + "\n")


def where_far(work):
    """Per shape and push angle: the calibrated model's final errors (arena at
    the first setting), from the evaluation's stored per-trial results."""
    import csv
    import sqlite3
    csv.field_size_limit(1 << 30)
    after = load(f"{work}/evaluate_after.json")
    key = after["settings"][0]["model_key"]
    params = {}
    with open(f"{work}/dataset/trials.csv", newline="") as f:
        for row in csv.DictReader(f):
            params[row["seed"]] = (row["shape"], abs(float(row["push_angle_rad"])) * DEG)
    con = sqlite3.connect(f"file:{work}/real.db?mode=ro", uri=True)
    cells = {}
    for seed, detail, pos, ang in con.execute(
            "SELECT t.seed, r.detail_json, r.final_position_error, r.final_angle_error "
            "FROM evaluation_results r JOIN trials t ON t.id = r.trial_id "
            "WHERE r.evaluation_id = ? AND r.model_key = ? AND r.status = 'ok'",
            (after["evaluation_id"], key)):
        shape, angle = params[str(seed)]
        band = "0-10°" if angle < 10 else "10-45°" if angle < 45 else "45-70°" if angle < 70 \
            else "70-90°"
        o = json.loads(detail)["outcome"]
        cells.setdefault((shape, band), []).append(
            (pos * 1e3, ang * DEG, abs(o["true"][2]) * DEG))
    rows = []
    for (shape, band), v in sorted(cells.items()):
        rows.append([shape, band, len(v), f"{sum(p for p, _, _ in v) / len(v):.2f}",
                     f"{max(p for p, _, _ in v):.2f}", f"{sum(a for _, a, _ in v) / len(v):.2f}",
                     f"{max(a for _, a, _ in v):.2f}", f"{sum(t for _, _, t in v) / len(v):.1f}"])
    return key, table(["shape", "push angle (abs)", "trials", "position mm mean", "max",
                       "angle ° mean", "max", "measured turn ° mean"], rows)


def cells(text):
    """The table cells of a block, wall-time columns dropped."""
    out = []
    header = None
    for line in text.splitlines():
        line = line.strip()
        if not line.startswith("|"):
            header = None
            if line:
                out.append(line)
            continue
        row = [c.strip() for c in line.strip("|").split("|")]
        if header is None:
            header = row
        if set("".join(row)) <= set("-"):
            continue
        out.append([c for h, c in zip(header, row) if "ms/trial" not in h])
    return out


def check(doc, generated):
    text = open(doc).read()
    if BEGIN not in text or END not in text:
        print(f"real_data_study: {doc} has no {BEGIN} ... {END} block", file=sys.stderr)
        return 1
    quoted = text.split(BEGIN, 1)[1].split(END, 1)[0]
    a, b = cells(quoted), cells(generated)
    if a == b:
        print(f"real_data_study: the figures {doc} quotes are the ones the study gives")
        return 0
    print(f"real_data_study: {doc} quotes figures the study no longer gives:", file=sys.stderr)
    for x, y in zip(a, b):
        if x != y:
            print(f"  quoted:    {x}\n  the study: {y}", file=sys.stderr)
    if len(a) != len(b):
        print(f"  ({len(a)} lines quoted, {len(b)} given)", file=sys.stderr)
    return 1


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--work", required=True)
    ap.add_argument("--total", type=float, default=0)
    ap.add_argument("--settings", default="")
    ap.add_argument("--check", action="append", default=[],
                    help="a document quoting the tables (repeatable)")
    ap.add_argument("--plot", help="also draw where the model is far from the data (SVG)")
    a = ap.parse_args()
    if a.plot:
        plot(a.work, a.plot)
    md = build(a.work, a.settings)
    times = open(f"{a.work}/times.txt").read().split()
    steps = ", ".join(f"{times[i]} {float(times[i + 1]):.1f} s" for i in range(0, len(times), 2))
    print(BEGIN)
    print(md)
    print(END)
    print(f"\nstudy wall time: {a.total:.1f} s ({steps})")
    with open(f"{a.work}/results.md", "w") as f:
        f.write(md + "\n")
    return max([check(doc, md) for doc in a.check], default=0)


if __name__ == "__main__":
    sys.exit(main())

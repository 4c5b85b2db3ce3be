#!/usr/bin/env python3
"""What "inertia" costs and changes on scenes (docs/scene.md, "What decides inertia").

Runs `arena simulate` on each scene twice, "carried" and "quasi_static", and prints per scene
the steps, the quasi-static run's extra solves and its steps that found no balance (carried),
how far the final poses differ, and both wall times; then the totals.

  scripts/inertia_study.py --arena build/bin/arena --scenes FILE [--dt S] [--every N]

--scenes  a scene file (.json) or a scenes.jsonl (one {"scene": ...} per line, as
          `arena import push-dataset` writes it)
--dt      override model.dt (the real-data study's arena setting is 0.016)
--every   take every Nth scene of a .jsonl (default 5)
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile


def simulate(arena, scene, inertia, dt):
    s = json.loads(json.dumps(scene))
    s.setdefault("model", {})["inertia"] = inertia
    if dt:
        s["model"]["dt"] = dt
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(s, f)
    try:
        out = subprocess.run([arena, "simulate", f.name], capture_output=True, text=True)
    finally:
        os.unlink(f.name)
    if out.returncode != 0:
        sys.exit(f"inertia_study: arena simulate failed ({inertia}): {out.stderr.strip()}")
    return json.loads(out.stdout)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arena", required=True)
    ap.add_argument("--scenes", required=True)
    ap.add_argument("--dt", type=float, default=None)
    ap.add_argument("--every", type=int, default=5)
    a = ap.parse_args()
    if a.scenes.endswith(".jsonl"):
        lines = open(a.scenes).read().splitlines()
        scenes = [json.loads(l)["scene"] for l in lines[:: a.every]]
    else:
        scenes = [json.load(open(a.scenes))]
    print("| scene | steps | quasi-static extra solves | steps carried | Δ position (mm) "
          "| Δ angle (mrad) | wall carried (s) | wall quasi-static (s) |")
    print("|---|---|---|---|---|---|---|---|")
    tot = {"steps": 0, "solves": 0, "carried": 0, "wc": 0.0, "wq": 0.0}
    for k, scene in enumerate(scenes):
        c = simulate(a.arena, scene, "carried", a.dt)
        q = simulate(a.arena, scene, "quasi_static", a.dt)
        dp = max(abs(x - y) for x, y in zip(c["final"]["position"], q["final"]["position"]))
        dr = max(abs(x - y) for x, y in zip(c["final"]["rpy"], q["final"]["rpy"]))
        s = q["solver"]
        print(f"| {k} | {s['steps']} | {s['quasi_static_solves']} | {s['quasi_static_carried']} "
              f"| {1e3 * dp:.3f} | {1e3 * dr:.2f} | {c['wall_s']:.3f} | {q['wall_s']:.3f} |")
        tot["steps"] += s["steps"]
        tot["solves"] += s["quasi_static_solves"]
        tot["carried"] += s["quasi_static_carried"]
        tot["wc"] += c["wall_s"]
        tot["wq"] += q["wall_s"]
    print(f"| all {len(scenes)} | {tot['steps']} | {tot['solves']} | {tot['carried']} "
          f"({100.0 * tot['carried'] / max(1, tot['steps']):.0f} %) | | | {tot['wc']:.3f} "
          f"| {tot['wq']:.3f} ({tot['wq'] / max(1e-12, tot['wc']):.1f}x) |")


if __name__ == "__main__":
    main()

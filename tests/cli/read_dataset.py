#!/usr/bin/env python3
"""Reads an arena dataset back without arena, as a lab's analysis script would,
and checks what the manifest promises. Usage: read_dataset.py DIR.

Exit 0: all checks hold; 1: a check failed (message on stderr); 77: the
reader it needs (h5py, for an HDF5 dataset) is not installed.
"""
import csv
import hashlib
import json
import math
import os
import sys


def fail(msg):
    print("read_dataset: " + msg, file=sys.stderr)
    sys.exit(1)


def check(cond, msg):
    if not cond:
        fail(msg)


def number(text):
    return float("nan") if text == "" else float(text)


def main():
    d = sys.argv[1]
    with open(os.path.join(d, "manifest.json")) as f:
        m = json.load(f)
    for entry in m["files"]:
        with open(os.path.join(d, entry["path"]), "rb") as f:
            data = f.read()
        check(len(data) == entry["bytes"], entry["path"] + ": size")
        check(hashlib.sha256(data).hexdigest() == entry["sha256"], entry["path"] + ": sha256")
    with open(os.path.join(d, "trials.csv"), newline="") as f:
        trials = list(csv.DictReader(f))
    check(len(trials) == m["counts"]["trials"] and trials, "trials.csv rows")
    params = m["parameters"]
    check("pivot_offset" in params and "push_distance" in params, "parameters: %s" % params)
    for row in trials:
        scene = json.loads(row["scene_json"])
        check("fingers" in scene and "pusher" in scene, "scene_json of trial " + row["trial_id"])
        check(row["pivot_offset"] != "", "pivot_offset of trial " + row["trial_id"])
        check(row["grasp_kept"] in ("0", "1"), "grasp_kept of trial " + row["trial_id"])
        check(row["predicted_status"] in ("ok", "solver_failure", "invalid_scene", "error"),
              "predicted_status")
        check(row["predicted_by"] != "", "predicted_by of trial " + row["trial_id"])
    offsets = sorted({float(r["pivot_offset"]) for r in trials})
    check(len(offsets) >= 2, "pivot offsets %s: a 0 mm push must be told from a 10 mm one" % offsets)
    with open(os.path.join(d, "contacts.csv"), newline="") as f:
        contacts = list(csv.DictReader(f))
    check(len(contacts) == 3 * len(trials), "contacts.csv: 3 contacts per trial")
    for c in contacts:
        total = sum(float(c[k]) for k in ("stick_fraction", "slide_fraction", "separate_fraction"))
        check(abs(total - 1) < 1e-9, "contact fractions of trial %s sum to %g" % (c["trial_id"], total))
        check(float(c["slip_distance_m"]) >= 0, "slip distance")

    fmt = m["export_format"]
    dropped = 0
    if fmt == "hdf5":
        try:
            import h5py
        except ImportError:
            print("h5py is not installed (Debian: python3-h5py)", file=sys.stderr)
            sys.exit(77)
        import numpy as np
        with h5py.File(os.path.join(d, "dataset.h5"), "r") as h5:
            for t in m["trials"]:
                g = h5[t["group"]]
                obs = g["observed"]
                cols = [c.decode() if isinstance(c, bytes) else c for c in obs.attrs["columns"]]
                data = obs[()]
                check(data.shape[0] == t["samples"], "observed rows of " + t["group"])
                invalid = data[:, cols.index("valid")] == 0
                dropped += int(invalid.sum())
                check(np.isnan(data[invalid][:, 2:]).all(), "dropped rows must be NaN")
                check(not np.isnan(data[~invalid][:, 2:]).any(), "valid rows must be numbers")
                check(g["true"].shape[0] == t["samples"], "true rows")
                check(g["predicted"].shape[1] == g["true"].shape[1], "predicted columns")
                check("scene_json" in g.attrs and "pivot_offset" in g.attrs, "group attributes")
                check(g["contacts"].shape == (3, 6), "contacts matrix")
                pred = g.attrs["predicted_by"]
                check(len(pred) > 0, "predicted_by attribute")
    else:
        for t in m["trials"]:
            path = os.path.join(d, t["observed_file"])
            if fmt == "csv":
                with open(path, newline="") as f:
                    rows = list(csv.DictReader(f))
                get = lambda r, k: number(r[k])
            else:
                with open(path) as f:
                    rows = [json.loads(line) for line in f]
                get = lambda r, k: float("nan") if r[k] is None else float(r[k])
            check(len(rows) == t["samples"], "observed rows of trial %d" % t["trial_id"])
            for r in rows:
                if get(r, "valid") == 0:
                    dropped += 1
                    check(math.isnan(get(r, "x")), "a dropped observation has no x")
                else:
                    check(not math.isnan(get(r, "x")), "a valid observation has x")
            check(os.path.exists(os.path.join(d, t["predicted_file"])), "predicted file")
    print("read_dataset: %s: %d trials, %d dropped observations, parameters %s" %
          (fmt, len(trials), dropped, ",".join(params)))
    return 0


if __name__ == "__main__":
    sys.exit(main())

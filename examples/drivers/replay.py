#!/usr/bin/env python3
"""Reference driver for `arena cell --backend exec:COMMAND` (protocol 1).

A lab's robot driver has the same shape as this file: say hello with what the
hardware can do, then answer the cell's messages, one JSON object per line on
stdout, logging on stderr. This driver's "robot" is a recorded dataset (an
`arena export` directory in csv or jsonl format): it serves the trial whose
scene matches the commanded one, so a campaign can be scored against data
recorded elsewhere. Standard library only.

    arena cell --id lab1 --domain 7 --backend "exec:examples/drivers/replay.py DATASET"

Options (after DATASET), to exercise the cell's failure handling (tests):
    --fail-mode MODE   malformed | crash | hang | nan | disorder | refuse-all
                       misbehave while executing (only once, in whichever driver
                       process gets there first, when --fail-once FILE names a
                       marker file: the first to misbehave creates it)
    --resets           answer reset requests itself (reports the target as achieved)

Protocol (executors/README.md has the full table):
    -> {"type":"hello","protocol":1,...}               first line we write
    <- {"type":"prepare","trial_id":..,"scene":{..}}   -> ready | refused
    <- {"type":"execute",...}                          -> sample ... then done | failed
    <- {"type":"reset",...}                            -> reset_done | reset_failed
    <- {"type":"shutdown"}                             we exit
"""
import csv
import json
import math
import os
import sys
import time

PROTOCOL = 1


def log(*args):
    print("replay.py:", *args, file=sys.stderr, flush=True)


def send(message):
    # allow_nan=False: a NaN must never reach the cell as a number (the
    # --fail-mode nan test writes one on purpose, by hand).
    sys.stdout.write(json.dumps(message, allow_nan=False) + "\n")
    sys.stdout.flush()


# ----------------------------------------------------------------- dataset

def read_stream(dataset, fmt, trial_id):
    """The true stream of one trial as a list of {column: value} rows."""
    if fmt == "csv":
        path = os.path.join(dataset, "streams", f"{trial_id}_true.csv")
        with open(path, newline="") as f:
            return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]
    path = os.path.join(dataset, "streams", f"{trial_id}_true.jsonl")
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def physical(scene):
    """The scene without what does not change the physics (the predictor's model)."""
    return {k: v for k, v in scene.items() if k != "model"}


def same(a, b):
    """Scene parameters equal (numbers to 1e-9 relative)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return abs(a - b) <= 1e-9 * (1 + abs(a) + abs(b))
    return a == b


class Dataset:
    def __init__(self, path):
        self.path = path
        with open(os.path.join(path, "manifest.json")) as f:
            manifest = json.load(f)
        self.format = manifest.get("export_format")
        if self.format not in ("csv", "jsonl"):
            raise SystemExit(f"replay.py: {path}: export format {self.format!r} cannot be read "
                             "with the standard library; export with --format csv or jsonl, or serve "
                             "it without a driver: --backend replay:DIR")
        self.trials = []  # (trial_id, seed, scene)
        with open(os.path.join(path, "scenes.jsonl")) as f:
            for line in f:
                row = json.loads(line)
                if row.get("scene") is not None:
                    self.trials.append((row["trial_id"], str(row["seed"]), row["scene"]))
        self.served = {}  # scene index -> how often served (replicates take turns)

    def match(self, scene, seed):
        """The recorded trial for a commanded scene: same seed first, else in turn."""
        want = physical(scene)
        hits = [t for t in self.trials if same(physical(t[2]), want)]
        if not hits:
            return None
        for t in hits:
            if t[1] == str(seed):
                return t
        key = json.dumps(want, sort_keys=True)
        n = self.served.get(key, 0)
        self.served[key] = n + 1
        return hits[n % len(hits)]


def contacts_of(scene):
    names = [f.get("name", f"finger{i}") for i, f in enumerate(scene.get("fingers", []))]
    normals = [f["normal"] for f in scene.get("fingers", [])]
    if scene.get("pusher"):
        names.append("pusher")
        normals.append(scene["pusher"]["normal"])
    return names, normals


def to_sample(row, scene):
    names, normals = contacts_of(scene)
    modes = {0: "stick", 1: "slide", 2: "separate"}
    contacts = []
    for name, n in zip(names, normals):
        norm = math.sqrt(sum(x * x for x in n))
        n = [x / norm for x in n]
        force = [row[f"{name}_fx"], row[f"{name}_fy"], row[f"{name}_fz"]]
        fn = sum(a * b for a, b in zip(force, n))
        contacts.append({"normal_force": fn,
                         "tangential_force": [force[k] - fn * n[k] for k in range(3)],
                         "torque": [row[f"{name}_tx"], row[f"{name}_ty"], row[f"{name}_tz"]],
                         "mode": modes.get(int(row[f"{name}_mode"]), "separate")})
    pusher_force = contacts[-1] if scene.get("pusher") else None
    pf = [0.0, 0.0, 0.0]
    if pusher_force:
        name = "pusher"
        pf = [row[f"{name}_fx"], row[f"{name}_fy"], row[f"{name}_fz"]]
    return {"type": "sample", "t": row["t"],
            "position": [row["x"], row["y"], row["z"]],
            "orientation": [row["qw"], row["qx"], row["qy"], row["qz"]],
            "velocity": [row["vx"], row["vy"], row["vz"]],
            "angular_velocity": [row["wx"], row["wy"], row["wz"]],
            "pusher_position": [row["pusher_x"], row["pusher_y"], row["pusher_z"]],
            "pusher_force": pf,
            "contacts": contacts}


# ----------------------------------------------------------------- driver

def main(argv):
    if len(argv) < 2:
        raise SystemExit("usage: replay.py DATASET [--fail-mode MODE [--fail-once FILE]] [--resets]")
    dataset = Dataset(argv[1])
    fail_mode, fail_once, resets = None, None, False
    i = 2
    while i < len(argv):
        if argv[i] == "--fail-mode":
            fail_mode, i = argv[i + 1], i + 2
        elif argv[i] == "--fail-once":
            fail_once, i = argv[i + 1], i + 2
        elif argv[i] == "--resets":
            resets, i = True, i + 1
        else:
            raise SystemExit(f"replay.py: unknown option {argv[i]}")

    def misbehaving():
        """Whether to misbehave now (once over all driver processes with --fail-once)."""
        if not fail_mode or not fail_once:
            return bool(fail_mode)
        try:  # O_EXCL: of several drivers (one per cell) exactly one wins
            os.close(os.open(fail_once, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return True
        except FileExistsError:
            return False  # misbehaved once already: this driver is well

    send({"type": "hello", "protocol": PROTOCOL, "name": "replay.py",
          "truth": "recorded", "engine": f"recorded dataset {os.path.abspath(dataset.path)}",
          "contact_types": ["point", "line", "patch"], "emulates_defects": False,
          "resets": resets})
    log(f"serving {len(dataset.trials)} recorded trials from {dataset.path}")
    prepared = None  # (trial_id, scene) of the trial to execute
    for line in sys.stdin:
        if not line.strip():
            continue
        msg = json.loads(line)
        kind = msg.get("type")
        if kind == "prepare":
            scene = msg.get("scene")
            hit = dataset.match(scene, msg.get("seed")) if isinstance(scene, dict) else None
            if hit is None or (fail_mode == "refuse-all" and misbehaving()):
                prepared = None
                send({"type": "refused",
                      "reason": f"dataset {dataset.path} holds no trial with this scene"})
            else:
                prepared = (hit[0], hit[2])
                send({"type": "ready"})
        elif kind == "execute":
            if prepared is None:
                send({"type": "failed", "reason": "execute without a prepared trial"})
                continue
            trial_id, scene = prepared
            rows = read_stream(dataset.path, dataset.format, trial_id)
            misbehave = fail_mode != "refuse-all" and len(rows) > 2 and misbehaving()
            mode = fail_mode if misbehave else None
            for k, row in enumerate(rows):
                sample = to_sample(row, scene)
                if k == 2 and mode == "malformed":
                    sys.stdout.write("this is not json\n")
                    sys.stdout.flush()
                    break
                if k == 2 and mode == "crash":
                    # Half a trial is out (the cell streams what it has while
                    # we are quiet): the cell must fail it, not keep it.
                    log("crashing on purpose")
                    time.sleep(0.3)
                    os._exit(3)
                if k == 2 and mode == "hang":
                    log("hanging on purpose")
                    time.sleep(3600)
                if k == 2 and mode == "nan":
                    text = json.dumps(sample).replace(json.dumps(sample["position"][0]), "NaN", 1)
                    sys.stdout.write(text + "\n")
                    sys.stdout.flush()
                    break
                if k == 2 and mode == "disorder":
                    sample["t"] = 0.0  # time going back
                send(sample)
            else:
                send({"type": "done", "detail": {"recorded_trial": trial_id,
                                                 "dataset": os.path.abspath(dataset.path)}})
            prepared = None
        elif kind == "reset":
            target = msg["target"]
            send({"type": "reset_done", "achieved": target, "attempts": 1})
        elif kind == "shutdown":
            log("shutdown")
            return 0
        else:
            send({"type": "error", "message": f"unknown message type {kind!r}"})
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

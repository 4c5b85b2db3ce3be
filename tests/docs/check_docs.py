#!/usr/bin/env python3
"""Docs that cannot drift (issue 26): checks docs/, README.md and every room's
README.md against the repository and the built `arena` binary.

  check_docs.py --source DIR --arena BIN            the static checks
  check_docs.py --source DIR --arena BIN --examples the worked example of
      docs/campaigns.md, run again: every `$ arena query` block's output must
      be what the doc prints (--update rewrites the blocks instead)
  check_docs.py --source DIR --arena BIN --adaptive [--slow] the walk-through
      of docs/adaptive.md (run, status, decisions, calibrate, the calibrated
      campaign), run again and compared the same way

Static checks: no file of the repository names a file it lacks (the shared
design notes are not in it); README.md links every page of docs/; every
repository path a doc names exists; every `arena COMMAND` a doc shows is a
command of the binary; docs/architecture.md's topic count and table match
the topics schemas/src/dds.cpp registers. Exit 1 with one line per problem.
"""
import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile

NUMBER_WORDS = {2: "Two", 3: "Three", 4: "Four", 5: "Five", 6: "Six", 7: "Seven", 8: "Eight"}
# Written split so that this file does not name them itself.
MISSING_NOTES = ["DESIGN" + ".md", "SCENE" + ".md"]


def tracked_files(src):
    try:
        out = subprocess.run(["git", "-C", src, "ls-files"], capture_output=True, text=True,
                             check=True).stdout.split("\n")
        return [f for f in out if f]
    except (OSError, subprocess.CalledProcessError):
        files = []
        for root, dirs, names in os.walk(src):
            dirs[:] = [d for d in dirs if not d.startswith((".", "build"))]
            files += [os.path.relpath(os.path.join(root, n), src) for n in names]
        return files


def doc_files(src, files):
    return sorted(f for f in files
                  if f.endswith(".md") and (f.startswith("docs/") or "/" not in f or
                                            f.count("/") == 1 and f.endswith("README.md")))


def check_missing_notes(src, files, problems):
    for f in files:
        path = os.path.join(src, f)
        try:
            text = open(path, encoding="utf-8", errors="replace").read()
        except OSError:
            continue
        for name in MISSING_NOTES:
            for n, line in enumerate(text.split("\n"), 1):
                if name in line:
                    problems.append(f"{f}:{n}: names {name}, which the repository lacks")


def check_docs_mentions(src, files, problems):
    """Every docs page any file of the repository names exists."""
    for f in files:
        try:
            text = open(os.path.join(src, f), encoding="utf-8", errors="replace").read()
        except OSError:
            continue
        for m in set(re.findall(r"\bdocs/([A-Za-z0-9_-]+\.md)\b", text)):
            if not os.path.exists(os.path.join(src, "docs", m)):
                problems.append(f"{f}: names docs/{m}, which does not exist")


def check_readme_lists_docs(src, files, problems):
    readme = open(os.path.join(src, "README.md"), encoding="utf-8").read()
    for f in files:
        if f.startswith("docs/") and f.endswith(".md") and f"({f})" not in readme:
            problems.append(f"README.md: does not link {f}")


TOP_DIRS = None


def check_paths(src, docs, problems):
    tops = {p for p in os.listdir(src) if os.path.isdir(os.path.join(src, p))
            and not p.startswith(".") and not p.startswith("build")}
    for f in docs:
        text = open(os.path.join(src, f), encoding="utf-8").read()
        base = os.path.dirname(f)
        # Markdown links to files of the repository.
        for m in re.finditer(r"\]\(([^)#\s]+)(#[^)]*)?\)", text):
            target = m.group(1)
            if re.match(r"^[a-z]+:", target):
                continue
            if not os.path.exists(os.path.normpath(os.path.join(src, base, target))):
                problems.append(f"{f}: links {target}, which does not exist")
        # `dir/file.ext` in code spans, for the repository's own folders.
        for m in re.finditer(r"`([A-Za-z0-9_./-]+)`", text):
            token = m.group(1)
            first = token.split("/")[0]
            if "/" not in token or first not in tops or not re.search(r"\.[a-z]+$", token):
                continue
            if not os.path.exists(os.path.join(src, token)):
                problems.append(f"{f}: names {token}, which does not exist")


def arena_commands(arena):
    out = subprocess.run([arena, "--help"], capture_output=True, text=True).stdout
    commands = set()
    in_list = False
    for line in out.split("\n"):
        if line.strip().upper().startswith("SUBCOMMANDS"):
            in_list = True
            continue
        if in_list:
            m = re.match(r"^\s+([a-z][a-z-]*)\b", line)
            if m:
                commands.add(m.group(1))
    return commands


def check_commands(src, docs, arena, problems):
    known = arena_commands(arena)
    if not known:
        problems.append(f"{arena} --help lists no commands")
        return
    for f in docs:
        text = open(os.path.join(src, f), encoding="utf-8").read()
        for m in re.finditer(r"(?:^\$ |`)arena ([a-z][a-z-]*)", text, re.M):
            if m.group(1) not in known:
                problems.append(f"{f}: shows `arena {m.group(1)}`, not a command of arena "
                                f"({', '.join(sorted(known))})")


def check_map_metrics(src, arena, problems):
    """The metrics README.md names for `arena plot --map` are ones the binary
    takes (it said "error", which `--metric` refuses)."""
    out = subprocess.run([arena, "plot", "--help"], capture_output=True, text=True).stdout
    m = re.search(r"--metric TEXT\s+.*?one of ([a-z_, ]+)", out)
    if not m:
        problems.append("arena plot --help lists no --metric names")
        return
    known = {w.strip() for w in m.group(1).split(",")}
    readme = open(os.path.join(src, "README.md"), encoding="utf-8").read()
    row = next((l for l in readme.split("\n") if "--map X,Y --metric M" in l), "")
    cells = row.split(" | ")
    described = cells[1] if len(cells) > 1 else ""
    m = re.search(r"a metric \(([^)]*)\)", described)
    if not m:
        problems.append("README.md: the --map row does not name its metrics as 'a metric (...)'")
        return
    for name in re.findall(r"[a-z_]+", re.sub(r"`--metric`|`arena plot --help`[^,)]*", "",
                                              m.group(1))):
        if name not in known and name not in ("lists", "them"):
            problems.append(f"README.md: names --metric {name}, which arena plot refuses "
                            f"(one of {', '.join(sorted(known))})")


def check_topics(src, problems):
    dds = open(os.path.join(src, "schemas/src/dds.cpp"), encoding="utf-8").read()
    topics = re.findall(r'kTopic = "([A-Za-z]+)"', dds)
    arch = open(os.path.join(src, "docs/architecture.md"), encoding="utf-8").read()
    word = NUMBER_WORDS.get(len(topics), str(len(topics)))
    if not re.search(rf"\b{word} topics\b", arch, re.I):
        problems.append(f"docs/architecture.md: does not say '{word} topics' "
                        f"(schemas/src/dds.cpp registers {len(topics)}: {', '.join(topics)})")
    for t in topics:
        if f"| `{t}` |" not in arch:
            problems.append(f"docs/architecture.md: the topic table has no row for {t}")


# ---------------------------------------------------------------- scene.md's simulate output

SIMULATE_UNCHECKED = ("wall_s", "residuals")  # host time; rounding-level residuals


def _sig_round(x, literal):
    """x rounded to as many significant digits as the doc's literal shows."""
    digits = len(re.sub(r"^[-0.]+", "", literal.split("e")[0].replace(".", ""))) or 1
    return float(f"{x:.{digits}g}")


def _compare_json(doc, got, literals, path, problems):
    if isinstance(doc, dict):
        if not isinstance(got, dict) or set(doc) != set(got):
            problems.append(f"docs/scene.md: simulate output {path or '{}'} has keys "
                            f"{sorted(got) if isinstance(got, dict) else got}, the doc shows "
                            f"{sorted(doc)}")
            return
        for k in doc:
            if k not in SIMULATE_UNCHECKED:
                _compare_json(doc[k], got[k], literals, f"{path}.{k}".lstrip("."), problems)
    elif isinstance(doc, list):
        # A list the doc shortens (contacts: the first one) is compared on its length.
        if not isinstance(got, list) or len(got) < len(doc):
            problems.append(f"docs/scene.md: simulate output {path} is {got}, the doc shows {doc}")
            return
        for i, d in enumerate(doc):
            _compare_json(d, got[i], literals, f"{path}[{i}]", problems)
    elif isinstance(doc, bool) or isinstance(doc, str) or doc is None:
        if doc != got:
            problems.append(f"docs/scene.md: simulate output {path} is {got!r}, the doc shows "
                            f"{doc!r}")
    else:
        literal = literals.pop(0) if literals else repr(doc)
        value = 0.0 if abs(got) < 1e-9 else _sig_round(got, literal)
        if value != float(doc):
            problems.append(f"docs/scene.md: simulate output {path} is {got}, the doc shows "
                            f"{literal}")


def _number_literals(text):
    """The doc's numbers in order, as written (for their significant digits)."""
    strings = re.sub(r'"(?:[^"\\]|\\.)*"', '""', text)
    return re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", strings)


def check_simulate_example(src, arena, problems, update=False):
    """docs/scene.md's `arena simulate` output is what the scene at the top of
    the page prints: same keys, every number to the digits the doc shows."""
    import json
    doc_path = os.path.join(src, "docs/scene.md")
    text = open(doc_path, encoding="utf-8").read()
    blocks = list(re.finditer(r"```json\n(.*?)```\n", text, re.S))
    scene = blocks[0].group(1)
    shown = next((b for b in blocks if b.group(1).startswith('{"ok": true')), None)
    if shown is None:
        problems.append("docs/scene.md: no `arena simulate` output block ({\"ok\": true, ...)")
        return
    with tempfile.TemporaryDirectory(prefix="arena-docs-scene-") as tmp:
        path = os.path.join(tmp, "scene.json")
        open(path, "w").write(scene)
        got = subprocess.run([arena, "simulate", path], capture_output=True, text=True,
                             timeout=120)
    try:
        actual = json.loads(got.stdout)
    except ValueError:
        problems.append(f"docs/scene.md: the scene at the top does not simulate: "
                        f"{got.stdout}{got.stderr}")
        return
    doc = json.loads(shown.group(1))
    # Literals in document order, skipping the unchecked keys' values.
    body = shown.group(1)
    for key in SIMULATE_UNCHECKED:
        body = re.sub(rf'"{key}": (\{{[^}}]*\}}|[-\d.e]+)', f'"{key}": null', body)
    before = len(problems)
    _compare_json(doc, actual, _number_literals(body), "", problems)
    if update and len(problems) > before:
        del problems[before:]
        new = _format_simulate(actual)
        text = text[:shown.start(1)] + new + text[shown.end(1):]
        open(doc_path, "w", encoding="utf-8").write(text)
        print("docs/scene.md: simulate output updated")


def _format_simulate(actual):
    import json

    def rounded(v):
        if isinstance(v, float):
            return 0 if abs(v) < 1e-9 else float(f"{v:.4g}")
        if isinstance(v, list):
            return [rounded(x) for x in v]
        if isinstance(v, dict):
            return {k: rounded(x) for k, x in v.items()}
        return v
    order = ["ok", "model", "final", "pusher_force", "contacts", "residuals", "solver", "grasp",
             "oscillation", "wall_s"]
    keys = [k for k in order if k in actual] + [k for k in actual if k not in order]
    lines = []
    for k in keys:
        v = actual[k]
        if k == "contacts":
            v = v[:1]
        if k in SIMULATE_UNCHECKED:  # shown to one digit: their order of magnitude
            v = {r: float(f"{x:.0e}") for r, x in v.items()} if isinstance(v, dict) else \
                float(f"{v:.0e}")
        else:
            v = rounded(v)
        lines.append(f'"{k}": ' + json.dumps(v, separators=(", ", ": ")))
    return "{" + ",\n ".join(lines) + "}\n"


# ---------------------------------------------------------------- examples

def doc_blocks(text):
    """(start, end, command, output) of every ``` block starting with `$ arena`:
    the command runs on while a line ends with a backslash or a quote is open."""
    blocks = []
    for m in re.finditer(r"```\n(\$ arena .*?)```\n", text, re.S):
        lines = m.group(1).split("\n")
        parts = [lines[0][2:]]
        k = 1
        while k < len(lines) and (parts[-1].endswith("\\") or
                                  " ".join(parts).count('"') % 2 == 1):
            parts.append(lines[k].strip())
            k += 1
        cmd = " ".join(p[:-1].strip() if p.endswith("\\") else p for p in parts)
        output = "\n".join(lines[k:])
        blocks.append((m.start(1), m.end(1), cmd, output))
    return blocks


# Lines of `arena run`'s output that depend on the host (time, rates, the
# DDS domain picked, orchestration times) are not compared; every other
# line the doc shows must be printed as shown.
VARIABLE_RUN_LINES = ("  time ", "  predictor ", "  orchestration ", "              and reset",
                      "campaign 1 'grip-slip': 24 trials on")


def run_examples(src, arena, update, problems):
    doc_path = os.path.join(src, "docs/campaigns.md")
    text = open(doc_path, encoding="utf-8").read()
    rel = lambda argv: [os.path.join(src, a) if a.startswith("examples/") else a for a in argv]
    with tempfile.TemporaryDirectory(prefix="arena-docs-") as tmp:
        new_text = text
        ran = None
        blocks = doc_blocks(text)
        # In the doc's order: submit (own store), run, queries, export.
        outputs = {}
        for start, end, cmd, expected in blocks:
            argv = shlex.split(cmd)
            verb = argv[1]
            if verb == "submit":
                sub = os.path.join(tmp, "submit")
                os.makedirs(sub)
                got = subprocess.run([arena] + rel(argv[1:]), capture_output=True, text=True,
                                     cwd=sub, timeout=120)
                printed = got.stdout + got.stderr
                for line in expected.strip().split("\n"):
                    if line and line not in printed:
                        problems.append(f"docs/campaigns.md: `{cmd}` no longer prints {line!r}")
            elif verb == "run":
                got = subprocess.run([arena] + rel(argv[1:]) + ["--quiet"], capture_output=True,
                                     text=True, cwd=tmp, timeout=300)
                if got.returncode != 0:
                    problems.append(f"docs/campaigns.md: the worked example's run exited "
                                    f"{got.returncode}: {got.stderr.strip()[-400:]}")
                    return
                ran = got.stdout
                shown = expected.split("\n$ ")[0]  # the run's own output, not the next command's
                for line in shown.strip().split("\n"):
                    if not line or line.startswith(VARIABLE_RUN_LINES):
                        continue
                    if line not in ran.split("\n"):
                        problems.append(f"docs/campaigns.md: `arena run` no longer prints\n"
                                        f"{line}\nit prints\n{ran}")
            elif verb in ("query", "export"):
                if ran is None:
                    problems.append("docs/campaigns.md: a query before the run")
                    return
                got = subprocess.run([arena] + argv[1:], capture_output=True, text=True, cwd=tmp,
                                     timeout=120)
                output = got.stdout + (got.stderr if verb == "export" else "")
                if output.strip() != expected.strip():
                    if update:
                        outputs[(start, end)] = (expected, output)
                    else:
                        problems.append(f"docs/campaigns.md: `{cmd[:60]}...` now prints\n"
                                        f"{output}where the doc says\n{expected}")
        # The Python read-back: run as shown, its output compared with the block after it.
        m = re.search(r"```python\n(.*?)```\n.*?```\n(.*?)```", text, re.S)
        if m:
            got = subprocess.run([sys.executable, "-c", m.group(1)], capture_output=True,
                                 text=True, cwd=tmp, timeout=120)
            if got.stdout.strip() != m.group(2).strip():
                problems.append(f"docs/campaigns.md: the Python read-back now prints\n"
                                f"{got.stdout}{got.stderr}where the doc says\n{m.group(2)}")
        for (start, end), (expected, output) in sorted(outputs.items(), reverse=True):
            body = new_text[start:end]
            new_text = new_text[:start] + body[:len(body) - len(expected)] + output + \
                new_text[end:]
        if update and new_text != text:
            open(doc_path, "w", encoding="utf-8").write(new_text)
            print("docs/campaigns.md: outputs updated")


# ---------------------------------------------------------------- adaptive walk-through

def _lines(text):
    return [l.rstrip() for l in text.strip("\n").split("\n")]


def _section(output, head):
    """The lines of `output` from the line `head` to the next blank line."""
    lines = output.split("\n")
    for i, l in enumerate(lines):
        if l.rstrip() == head:
            j = i
            while j < len(lines) and lines[j].strip():
                j += 1
            return "\n".join(lines[i:j]) + "\n"
    return ""


def _check_calibration_claims(out, problems):
    """What docs/adaptive.md concludes from calibrate's first table: the fingers'
    scale near the cells' 1.3 with a profile that brackets it, the pusher's not
    identified, the held-out loss lower after the fit."""
    m = re.search(r"^mu_fingers\s+([\d.]+)\s+[\d.]+\s+\[\s*([\d.]+),\s*([\d.]+)\]\s+"
                  r"\[\s*([\d.]+),\s*([\d.]+)\]", out, re.M)
    if not m:
        problems.append("docs/adaptive.md: calibrate printed no mu_fingers row with a profile")
        return
    fit, lo, hi = float(m.group(1)), float(m.group(4)), float(m.group(5))
    if abs(fit / 1.3 - 1) > 0.05:
        problems.append(f"docs/adaptive.md: says mu_fingers fits within 5 % of 1.3; it fits {fit}")
    if not lo <= 1.3 <= hi:
        problems.append(f"docs/adaptive.md: says the profile brackets 1.3; it is [{lo}, {hi}]")
    if "mu_pusher: NOT IDENTIFIED" not in out:
        problems.append("docs/adaptive.md: says mu_pusher is not identified; calibrate no longer "
                        "says so")
    m = re.search(r"loss \(weighted\)\s+([\d.]+)\s+([\d.]+)", out)
    if not m or float(m.group(2)) >= float(m.group(1)):
        problems.append("docs/adaptive.md: says the held-out loss falls; it does not")
    for name in ("position \\(mm\\)", "angle \\(deg\\)", "force RMS \\(N\\)"):
        m = re.search(name + r"\s+([\d.]+)\s+([\d.]+)", out)
        if not m or float(m.group(2)) >= float(m.group(1)):
            problems.append(f"docs/adaptive.md: says every held-out error falls at the campaign's "
                            f"settings; {name} does not")


def _model_error(out):
    m = re.search(r"final position ([\d.]+) mm, final angle ([\d.]+) deg,\s+contact force "
                  r"([\d.]+) N RMS", out)
    return tuple(float(g) for g in m.groups()) if m else None


def _check_calibrated_run_claims(first, second, problems):
    """Section 3: the calibrated campaign's median position, angle and force
    errors are each below half the uncalibrated one's."""
    a, b = _model_error(first), _model_error(second)
    if not a or not b:
        problems.append("docs/adaptive.md: a run printed no model error line")
        return
    if not all(b[i] < a[i] / 2 for i in range(3)):
        problems.append(f"docs/adaptive.md: says calibration lowers the median position, angle "
                        f"and force errors below half; uncalibrated {a}, calibrated {b} "
                        f"(position mm, angle deg, force N)")


def run_adaptive(src, arena, update, slow, problems):
    """docs/adaptive.md's walk-through, sections 1-3, run again. The sampler's
    batch is fixed in the campaign, so which trials it takes does not depend on
    which cell answers first, and each trial's truth is its own: every figure
    is reproducible. Blocks compared: `arena run` (its host-dependent lines
    aside), the "adaptive sampling:" section of `arena status`, `arena query`
    and `arena calibrate` in full. The calibration at the cell's fidelity is
    slow (minutes): run only with --slow; without it the doc must say it is a
    recorded run."""
    doc_path = os.path.join(src, "docs/adaptive.md")
    text = open(doc_path, encoding="utf-8").read()
    end = text.find("### 4.")
    rel = lambda argv: [os.path.join(src, a) if a.startswith(("examples/", "tests/")) else a
                        for a in argv]
    outputs = {}
    with tempfile.TemporaryDirectory(prefix="arena-docs-adaptive-") as tmp:
        calibrations = 0
        runs = []
        for start, stop, cmd, expected in doc_blocks(text[:end]):
            argv = shlex.split(cmd)
            verb = argv[1]
            if verb == "calibrate" and "--predictor-settings" in argv and not slow:
                if "recorded run" not in text[stop:stop + 400]:
                    problems.append("docs/adaptive.md: the calibration at the cell's settings is "
                                    "not re-run by the docs test, so the text after it must say "
                                    "'recorded run'")
                continue
            extra = ["--quiet"] if verb == "run" else []
            got = subprocess.run([arena] + rel(argv[1:]) + extra, capture_output=True, text=True,
                                 cwd=tmp, timeout=3600)
            output = got.stdout
            if verb == "calibrate":
                calibrations += 1
                if got.returncode != 0:
                    problems.append(f"docs/adaptive.md: `{cmd[:70]}` exited {got.returncode}: "
                                    f"{got.stderr.strip()[-400:]}")
                    return
                if calibrations == 1:
                    _check_calibration_claims(output, problems)
            elif got.returncode != 0:
                problems.append(f"docs/adaptive.md: `{cmd[:70]}` exited {got.returncode}: "
                                f"{got.stderr.strip()[-400:]}")
                return
            if verb == "run":
                runs.append(output)
                if len(runs) == 2:
                    _check_calibrated_run_claims(runs[0], runs[1], problems)
                shown = [l for l in _lines(expected)
                         if l and not l.startswith(VARIABLE_RUN_LINES) and l.strip() != "..."]
                have = _lines(output)
                missing = [l for l in shown if l not in have]
                if missing and not update:
                    problems.append(f"docs/adaptive.md: `arena run` no longer prints\n"
                                    + "\n".join(missing) + f"\nit prints\n{output}")
                if missing:
                    outputs[(start, stop)] = (expected, output)
                continue
            if verb == "calibrate" and calibrations > 1:
                # The recorded run at the cell's settings is shown from its table on.
                have = _lines(output)
                missing = [l for l in _lines(expected) if l and l not in have]
                if missing:
                    problems.append(f"docs/adaptive.md: `{cmd[:70]}` no longer prints\n" +
                                    "\n".join(missing) + f"\nit prints\n{output}")
                continue
            if verb == "status":
                output = _section(output, "adaptive sampling:")
            if _lines(output) != _lines(expected):
                if update:
                    outputs[(start, stop)] = (expected, output)
                else:
                    problems.append(f"docs/adaptive.md: `{cmd[:70]}` now prints\n{output}"
                                    f"where the doc says\n{expected}")
    new_text = text
    for (start, stop), (expected, output) in sorted(outputs.items(), reverse=True):
        body = new_text[start:stop]
        new_text = new_text[:start] + body[:len(body) - len(expected)] + output + new_text[stop:]
    if update and new_text != text:
        open(doc_path, "w", encoding="utf-8").write(new_text)
        print("docs/adaptive.md: outputs updated")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--source", required=True)
    ap.add_argument("--arena", required=True)
    ap.add_argument("--examples", action="store_true")
    ap.add_argument("--update", action="store_true")
    ap.add_argument("--adaptive", action="store_true",
                    help="run docs/adaptive.md's walk-through (sections 1-3) again")
    ap.add_argument("--slow", action="store_true",
                    help="with --adaptive: also the calibration at the cell's settings")
    a = ap.parse_args()
    a.arena = os.path.abspath(a.arena)  # the examples run in a scratch directory
    a.source = os.path.abspath(a.source)
    problems = []
    if a.adaptive:
        run_adaptive(a.source, a.arena, a.update, a.slow, problems)
    elif a.examples:
        run_examples(a.source, a.arena, a.update, problems)
    else:
        files = tracked_files(a.source)
        docs = doc_files(a.source, files)
        check_missing_notes(a.source, files, problems)
        check_docs_mentions(a.source, files, problems)
        check_readme_lists_docs(a.source, files, problems)
        check_paths(a.source, docs, problems)
        check_commands(a.source, docs, a.arena, problems)
        check_topics(a.source, problems)
        check_map_metrics(a.source, a.arena, problems)
        check_simulate_example(a.source, a.arena, problems, a.update)
    for p in problems:
        print(p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
